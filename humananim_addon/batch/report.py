"""What a batch tells its user: the progress line, the JSON summary and the HTML report.

The report is one self-contained HTML file in the output folder: one row per take (failures
first) with its status, the QA figures of its steps, its thumbnail (an SVG beside the results,
linked relatively) and, for a failure, the one-line error. No script, no server: it opens from
file:// in any browser. No bpy here.
"""

import html
import math
import os
import time

from .plan import write_json_atomic

SUMMARY = "summary.json"
REPORT = "report.html"
PROGRESS = "progress.json"


def stick_figure_svg(poses, size=(160, 120), title=""):
    """Bone segments [[head xyz, tail xyz], ...] per pose, later poses darker, seen from the side
    along the horizontal axis the motion spreads least on (Z up)."""
    points = [p for pose in poses for seg in pose for p in seg]
    xs = [p[0] for p in points]
    ys = [p[1] for p in points]
    zs = [p[2] for p in points]
    axis = 0 if (max(xs) - min(xs)) >= (max(ys) - min(ys)) else 1
    hs = xs if axis == 0 else ys
    w, h = size
    span = max(max(hs) - min(hs), max(zs) - min(zs), 1e-6)
    scale = 0.9 * min(w, h) / span if span else 1.0
    cx, cz = (max(hs) + min(hs)) / 2, (max(zs) + min(zs)) / 2

    def xy(p):
        return w / 2 + (p[axis] - cx) * scale, h / 2 - (p[2] - cz) * scale
    lines = []
    for i, pose in enumerate(poses):
        shade = int(200 - 170 * i / max(1, len(poses) - 1))
        colour = f"rgb({shade},{shade},{min(255, shade + 40)})"
        for head, tail in pose:
            (x1, y1), (x2, y2) = xy(head), xy(tail)
            lines.append(f'<line x1="{x1:.1f}" y1="{y1:.1f}" x2="{x2:.1f}" y2="{y2:.1f}" stroke="{colour}"/>')
    return (f'<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="{h}" viewBox="0 0 {w} {h}">'
            f'<title>{html.escape(title)}</title><rect width="{w}" height="{h}" fill="#fafafa"/>'
            f'<g stroke-width="1.6" stroke-linecap="round">{"".join(lines)}</g></svg>\n')


def progress_line(state, width=24):
    """`[#####.....] 5/12 done, 1 failed, 6 left, ETA 0:32`."""
    total = max(1, state["total"])
    finished = state["done"] + state["failed"]
    filled = int(width * finished / total)
    eta = state.get("eta_seconds")
    eta_text = "--:--" if eta is None else _clock(eta)
    return (f"[{'#' * filled}{'.' * (width - filled)}] {state['done']}/{state['total']} done, "
            f"{state['failed']} failed, {state['remaining']} left, ETA {eta_text}")


def _clock(seconds):
    seconds = int(round(seconds))
    h, rest = divmod(seconds, 3600)
    return f"{h}:{rest // 60:02d}:{rest % 60:02d}" if h else f"{rest // 60}:{rest % 60:02d}"


class Progress:
    """Counts of a running batch and its ETA (from this run's finished takes); written to
    progress.json (for the Blender panel) and drawn as a line on stderr."""

    def __init__(self, out_dir, total, skipped, stream=None):
        self.path = os.path.join(out_dir, PROGRESS)
        self.started = time.monotonic()
        self.stream = stream
        self.state = {"total": total, "done": skipped, "failed": 0, "skipped": skipped,
                      "remaining": total - skipped, "eta_seconds": None, "running": True, "pid": os.getpid()}
        self.update()

    def take_finished(self, ok):
        s = self.state
        s["done" if ok else "failed"] += 1
        s["remaining"] -= 1
        finished_now = s["done"] + s["failed"] - s["skipped"]
        elapsed = time.monotonic() - self.started
        s["eta_seconds"] = round(elapsed / finished_now * s["remaining"], 1) if finished_now else None
        self.update()

    def finish(self, status):
        self.state.update(running=False, status=status, eta_seconds=0 if status == "finished" else None)
        self.update(final=True)

    def update(self, final=False):
        self.state["elapsed_seconds"] = round(time.monotonic() - self.started, 1)
        write_json_atomic(self.path, self.state)
        if self.stream is not None:
            end = "\n" if final or not self.stream.isatty() else ""
            self.stream.write(("\r" if self.stream.isatty() else "") + "batch: " + progress_line(self.state) + end)
            self.stream.flush()


def take_summary(record, skipped=False):
    """The part of a take's record the summary and the report show."""
    steps = [{"command": s["command"], "seconds": s["seconds"], "qa": s.get("qa"),
              "measures": own_measures(s["result"]), "wrote": [os.path.basename(p) for p in s["result"].get("wrote", [])]}
             for s in record.get("steps", [])]
    out = {"name": record["name"], "file": record["file"], "status": record["status"],
           "skipped": skipped, "attempts": record.get("attempts"), "error": record.get("error"),
           "wall_seconds": record.get("wall_seconds"), "work_seconds": record.get("work_seconds"),
           "worker": record.get("worker"), "started_at": record.get("started_at"),
           "finished_at": record.get("finished_at"), "thumbnail": record.get("thumbnail"),
           "result_file": record.get("result_file"), "outputs": record.get("outputs", []), "steps": steps,
           "qa_passed": qa_state(steps),
           "qa_warnings": [f"{s['command']}: {w}" for s in steps for w in (s["qa"] or {}).get("warnings", [])]}
    return out


def write_summary(out_dir, summary):
    write_json_atomic(os.path.join(out_dir, SUMMARY), summary)
    path = os.path.join(out_dir, REPORT)
    with open(path + ".tmp", "w", encoding="utf-8") as f:
        f.write(html_report(summary))
    os.replace(path + ".tmp", path)
    return path


def qa_figures(step):
    """(label, value text, failed) of a step's QA: the measures of its `qa` object when the command
    reports one; otherwise the command's own measures of its result (errors, slides, peaks)."""
    qa = step.get("qa")
    if isinstance(qa, dict) and isinstance(qa.get("measures"), dict):
        out = []
        for name, m in qa["measures"].items():
            if not isinstance(m, dict) or m.get("value") is None:
                continue
            value = m["value"]
            text = f"{_fmt(value)} {m.get('unit', '')}".strip() if not isinstance(value, bool) else str(value)
            out.append((name, text, m.get("passed") is False))
        return out
    if isinstance(qa, dict):
        return [(k, _fmt(v), False) for k, v in qa.items() if _scalar(v)]
    return [(k, _fmt(v), False) for k, v in step.get("measures", {}).items()]


MEASURE_WORDS = ("error", "slide", "peak_", "falling", "ratio", "depth", "penetration", "tracking")


def own_measures(result):
    """A command's numeric figures about its result's quality (shown when it reports no `qa`)."""
    return {k: v for k, v in result.items() if isinstance(v, (int, float)) and not isinstance(v, bool)
            and any(w in k for w in MEASURE_WORDS) and not k.endswith(("_frame", "_at"))}


def qa_state(steps):
    """True when every step's QA passed, False when one failed, None when none was measured."""
    states = [s["qa"].get("passed") for s in steps if isinstance(s.get("qa"), dict) and "passed" in s["qa"]]
    if not states:
        return None
    return all(st is not False for st in states)


def _scalar(v):
    return isinstance(v, (int, float, str, bool)) or v is None


def _fmt(v):
    if isinstance(v, float):
        return "nan" if math.isnan(v) else f"{v:.4g}"
    return html.escape(str(v))


STYLE = """body{font:14px system-ui,sans-serif;margin:1.5em;color:#222}
table{border-collapse:collapse;width:100%}td,th{border-bottom:1px solid #ddd;padding:4px 8px;text-align:left;vertical-align:top}
tr.failed{background:#fde8e8}tr.failed td.status{color:#b00;font-weight:bold}td.status{color:#070}
.err{font-family:monospace;color:#b00}.qa{font-size:12px;color:#444}.qa b{font-weight:600}img{display:block}
.counts span{margin-right:1.5em}.bad{color:#b00;font-weight:600}"""


def html_report(summary):
    takes = sorted(summary["results"], key=lambda t: (t["status"] == "done", t["name"]))
    rows = []
    for t in takes:
        thumb = (f'<img src="{html.escape(t["name"])}/{html.escape(t["thumbnail"])}" width="160" height="120" '
                 f'alt="{html.escape(t["name"])}">' if t.get("thumbnail") and t["status"] == "done" else "")
        qa = "".join(
            f'<div class="qa"><b>{html.escape(s["command"])}</b> {s["seconds"]:.2f} s'
            + "".join(f' &middot; <span class="{"bad" if bad else "ok"}">{html.escape(k)} {v}</span>'
                      for k, v, bad in qa_figures(s)) + "</div>"
            for s in t["steps"])
        detail = f'<div class="err">{html.escape(t["error"] or "")}</div>' if t["status"] != "done" else qa
        link = (f'<a href="{html.escape(t["name"])}/{html.escape(t["result_file"])}">{html.escape(t["name"])}</a>'
                if t["status"] == "done" and t.get("result_file") else html.escape(t["name"]))
        status = t["status"] + (" (earlier run)" if t.get("skipped") else "")
        if t.get("qa_passed") is not None:
            status += "<br>QA " + ("passed" if t["qa_passed"] else f"{len(t['qa_warnings'])} warning(s)")
        rows.append(f'<tr class="{html.escape(t["status"])}" id="take-{html.escape(t["name"])}">'
                    f'<td class="name">{link}<div class="qa">{html.escape(os.path.basename(t["file"]))}</div></td>'
                    f'<td class="status">{status}</td><td class="thumb">{thumb}</td>'
                    f'<td class="detail">{detail}</td></tr>')
    c = summary
    return f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>HumanAnim batch: {c['done']} done, {c['failed']} failed</title>
<style>{STYLE}</style></head><body>
<h1>HumanAnim batch</h1>
<p>Pipeline: <code>{html.escape(' -> '.join(c['pipeline']))}</code><br>Engine: {html.escape(c['engine']['description'])}</p>
<p class="counts"><span id="done">{c['done']} done</span><span id="failed">{c['failed']} failed</span>
<span id="skipped">{c['skipped']} from earlier runs</span><span>{c['seconds']:.1f} s</span></p>
<table><thead><tr><th>Take</th><th>Status</th><th>Result</th><th>QA / error</th></tr></thead>
<tbody>
{chr(10).join(rows)}
</tbody></table></body></html>
"""
