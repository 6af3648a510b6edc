"""Batch pipelines over a mocap library: `python -m humananim batch`.

plan (inputs, manifest, pipeline, resumability), runner (Dask engines, one process per take,
atomic outputs), take (the per-take process), report (progress, JSON summary, HTML report),
job (the Blender panel's background job), flamenco_humananim_batch.js (a Flamenco job type).
Everything but `take` and the panel is free of bpy; dask is imported only when a batch runs."""

from .command import add_commands  # noqa: F401  (the command line finds commands here)
