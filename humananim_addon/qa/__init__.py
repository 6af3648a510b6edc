"""Motion QA: measuring a result, storing and reading its report on the armature (job.py). It has no
settings and no command of its own: every command's summary carries its QA (cli.qa_of_result)."""
