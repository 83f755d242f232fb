"""``rmbench report``: evaluation folders side by side, as in the benchmark's published table.

Rows are tasks grouped M(1) then M(n), with group and overall averages; columns are the
evaluated policies (each folder's summary.json), and optionally the published success rates.
Markdown, or HTML with bar charts and links to the videos.
"""

from __future__ import annotations

import html
import json
from pathlib import Path

from rmbench.eval.chance import chance
from rmbench.eval.harness import read_records
from rmbench.tasks.registry import ordered
from rmbench.video import write_atomic

# Success rates (%) published for the benchmark (100 rollouts, 50 demonstrations per task).
PUBLISHED = {
    "DP": {"observe_and_pickup": 1, "rearrange_blocks": 0, "put_back_block": 0, "swap_blocks": 11,
           "swap_T": 20, "battery_try": 10, "blocks_ranking_try": 10, "cover_blocks": 0,
           "press_button": 0},
    "ACT": {"observe_and_pickup": 1, "rearrange_blocks": 29, "put_back_block": 0, "swap_blocks": 2,
            "swap_T": 2, "battery_try": 19, "blocks_ranking_try": 0, "cover_blocks": 0,
            "press_button": 0},
    "Pi0.5": {"observe_and_pickup": 9, "rearrange_blocks": 13, "put_back_block": 11,
              "swap_blocks": 24, "swap_T": 15, "battery_try": 16, "blocks_ranking_try": 6,
              "cover_blocks": 0, "press_button": 0},
    "X-VLA": {"observe_and_pickup": 9, "rearrange_blocks": 13, "put_back_block": 18,
              "swap_blocks": 16, "swap_T": 3, "battery_try": 26, "blocks_ranking_try": 1,
              "cover_blocks": 2, "press_button": 0},
    "Mem-0": {"observe_and_pickup": 4, "rearrange_blocks": 89, "put_back_block": 90,
              "swap_blocks": 67, "swap_T": 14, "battery_try": 28, "blocks_ranking_try": 18,
              "cover_blocks": 68, "press_button": 0},
}


def load_runs(folders: list[str | Path], labels: list[str] | None = None) -> list[dict]:
    """Each folder's summary and videos; a column is named by its label, else by the policy
    spec the evaluation ran (which holds the checkpoint's path)."""
    if labels and len(labels) != len(folders):
        raise ValueError(f"{len(labels)} labels for {len(folders)} evaluation folders")
    runs = []
    for k, folder in enumerate(folders):
        path = Path(folder) / "summary.json"
        if not path.exists():
            raise ValueError(f"{folder}: no summary.json (not an `rmbench eval` folder)")
        summary = json.loads(path.read_text())
        videos = {}
        for task in summary["tasks"]:
            for r in read_records(Path(folder) / task / "episodes.jsonl"):
                if r.get("video"):
                    videos.setdefault(task, []).append((r["seed"], r["success"],
                                                        str(Path(folder) / task / r["video"])))
        runs.append({"name": labels[k] if labels else summary["policy"],
                     "policy": summary["policy"], "folder": str(folder), "summary": summary,
                     "videos": videos})
    return runs


def table(runs: list[dict], published: list[str], metric: str = "success_rate",
          tasks: list[str] | None = None, with_chance: bool = False
          ) -> tuple[list[str], list[list]]:
    """Header and rows: task, TMC, one value (%) of ``metric`` (success_rate or mean_progress)
    per column; None where not evaluated. Published numbers exist for success rates only, and
    so does the last column ``with_chance`` adds: the task's chance level for a policy
    without memory (``eval/chance.py``). ``tasks`` keeps only those rows (default: all nine)."""
    published = published if metric == "success_rate" else []
    with_chance = with_chance and metric == "success_rate"
    header = (["task", "TMC"] + [r["name"] for r in runs] + [f"{p} (published)" for p in published]
              + ["chance (no memory)"] * with_chance)
    rows: list[list] = []
    for group in ("M(1)", "M(n)"):
        names = [c.name for c in ordered() if c.tmc == group and (tasks is None or c.name in tasks)]
        if not names:
            continue
        group_rows = []
        for t in names:
            vals = [100 * r["summary"]["tasks"][t][metric] if t in r["summary"]["tasks"]
                    else None for r in runs] + [PUBLISHED[p][t] for p in published]
            vals += [100 * chance(t).rate] * with_chance
            group_rows.append([t, group, *vals])
        rows.extend(group_rows)
        rows.append([f"average {group}", group, *_averages(group_rows)])
    task_rows = [r for r in rows if not str(r[0]).startswith("average")]
    rows.append(["average (all)", "", *_averages(task_rows)])
    return header, rows


def _averages(rows: list[list]) -> list:
    out = []
    for k in range(2, len(rows[0])):
        vals = [r[k] for r in rows]
        out.append(None if any(v is None for v in vals) else sum(vals) / len(vals))
    return out


def _fmt(v) -> str:
    return "—" if v is None else f"{v:.1f}"


def markdown(runs: list[dict], published: list[str]) -> str:
    lines = []
    for metric, title in (("success_rate", "Success rate (%)"),
                          ("mean_progress", "Progress (mean of each episode's best, %)")):
        header, rows = table(runs, published, metric, with_chance=True)
        lines += [f"# {title}", "", "| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
        for r in rows:
            bold = str(r[0]).startswith("average")
            cells = [f"**{r[0]}**" if bold else r[0], r[1]] + [_fmt(v) for v in r[2:]]
            lines.append("| " + " | ".join(cells) + " |")
        lines.append("")
    lines += ["Runs: " + ", ".join(
        f"{r['name']}: `{r['policy']}` ({r['folder']})" if r["name"] != r["policy"]
        else f"`{r['name']}` ({r['folder']})" for r in runs), ""]
    return "\n".join(lines)


def html_report(runs: list[dict], published: list[str]) -> str:
    header, rows = table(runs, published)
    esc = html.escape
    colours = ["#4c78a8", "#f58518", "#54a24b", "#e45756", "#72b7b2", "#b279a2", "#ff9da6",
               "#9d755d", "#bab0ac"]
    out = ["<!doctype html><meta charset='utf-8'><title>rmbench report</title>",
           "<style>body{font-family:sans-serif;margin:2em}table{border-collapse:collapse}"
           "td,th{border:1px solid #ccc;padding:4px 8px;text-align:right}"
           "td:first-child{text-align:left}tr.avg{font-weight:bold;background:#f4f4f4}</style>",
           "<h1>Success rate (%)</h1><table><tr>"
           + "".join(f"<th>{esc(h)}</th>" for h in header) + "</tr>"]
    for r in rows:
        cls = " class='avg'" if str(r[0]).startswith("average") else ""
        out.append(f"<tr{cls}><td>{esc(str(r[0]))}</td><td>{esc(str(r[1]))}</td>"
                   + "".join(f"<td>{_fmt(v)}</td>" for v in r[2:]) + "</tr>")
    out.append("</table><h2>Per task</h2>")
    series = header[2:]
    bar_w, gap, height = 14, 10, 120
    task_rows = [r for r in rows if not str(r[0]).startswith("average")]
    width = len(task_rows) * (len(series) * bar_w + gap) + 40
    svg = [f"<svg width='{width}' height='{height + 90}' xmlns='http://www.w3.org/2000/svg'>"]
    for i, r in enumerate(task_rows):
        x0 = 30 + i * (len(series) * bar_w + gap)
        for k, v in enumerate(r[2:]):
            if v is None:
                continue
            h = height * v / 100
            svg.append(f"<rect x='{x0 + k * bar_w}' y='{height - h:.1f}' width='{bar_w - 2}' "
                       f"height='{h:.1f}' fill='{colours[k % len(colours)]}'>"
                       f"<title>{esc(series[k])}: {v:.1f}%</title></rect>")
        svg.append(f"<text x='{x0}' y='{height + 12}' font-size='10' transform='rotate(35 {x0} "
                   f"{height + 12})'>{esc(str(r[0]))}</text>")
    svg.append("</svg>")
    out.append("".join(svg))
    out.append("<p>" + " ".join(f"<span style='color:{colours[k % len(colours)]}'>&#9632;</span> "
                                f"{esc(s)}" for k, s in enumerate(series)) + "</p>")
    out.append("<h2>Videos</h2>")
    for run in runs:
        for task, vids in run["videos"].items():
            links = ", ".join(f"<a href='{esc(Path(p).resolve().as_uri())}'>seed {s}"
                              f"{'' if ok else ' (failed)'}</a>" for s, ok, p in vids)
            out.append(f"<p>{esc(run['name'])} / {esc(task)}: {links}</p>")
    return "\n".join(out) + "\n"


def write_report(folders: list[str | Path], out: str | Path, published: list[str],
                 labels: list[str] | None = None) -> Path:
    unknown = sorted(set(published) - set(PUBLISHED))
    if unknown:
        raise ValueError(f"no published numbers for {unknown}; known: {sorted(PUBLISHED)}")
    runs = load_runs(folders, labels)
    out = Path(out)
    text = html_report(runs, published) if out.suffix == ".html" else markdown(runs, published)
    write_atomic(out, text.encode())
    return out
