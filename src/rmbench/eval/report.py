"""``rmbench report``: evaluation folders side by side, as in the benchmark's published table.

Rows are tasks grouped M(1) then M(n), with group and overall averages; columns are the
evaluated policies (each folder's summary.json), and optionally the published success rates
(the paper's main results table, ``eval/published.json``).
Markdown, or HTML with bar charts and links to the videos. Every success rate carries its
Wilson 95% interval (``eval/intervals.py``): a published one too, over its 100 rollouts; an
average over tasks of equal episode counts, the interval of the pooled episodes (wider than
the average's own where the tasks' rates differ). A folder with a memory probe
(``rmbench eval --memory-reset``) adds its rates with and without and the drop.
"""

from __future__ import annotations

import html
from pathlib import Path

from rmbench.eval import published as _published
from rmbench.eval.chance import chance
from rmbench.eval.intervals import wilson
from rmbench.eval.records import read_records
from rmbench.eval.summary import drop_text, rate_text
from rmbench.files import read_json_object, write_atomic
from rmbench.tasks.registry import ordered

# Success rates (%) of the paper's main results table, per policy and task (eval/published.py)
PUBLISHED_ROLLOUTS = _published.rollouts()
PUBLISHED = _published.columns("main")


def published_source(table: str = "main") -> str:
    """The paper and table published columns come from: '2603.01229, main results table'."""
    return f"{_published.arxiv()}, {_published.table_name(table)} table"


class Rate(float):
    """A success rate in percent that knows its count: a float everywhere (averages, bars),
    and its Wilson 95% interval where a table prints it."""

    successes: int
    episodes: int

    def __new__(cls, successes: int, episodes: int) -> Rate:
        rate = super().__new__(cls, 100 * successes / episodes)
        rate.successes, rate.episodes = int(successes), int(episodes)
        return rate

    @classmethod
    def of(cls, row: dict) -> Rate | float:
        """From a summary's (or a table cell's) row; an older row without ``successes`` has
        it back from its rate and episodes."""
        n = row.get("episodes")
        if not n:
            return 100 * row["success_rate"]
        # the count where the row has one (a default argument would read the rate regardless)
        k = row["successes"] if "successes" in row else round(row["success_rate"] * n)
        return cls(k, n)

    @property
    def ci95(self) -> tuple[float, float]:
        low, high = wilson(self.successes, self.episodes)
        return 100 * low, 100 * high


def load_runs(folders: list[str | Path], labels: list[str] | None = None) -> list[dict]:
    """Each folder's summary and videos; a column is named by its label, else by the policy
    spec the evaluation ran (which holds the checkpoint's path)."""
    if labels and len(labels) != len(folders):
        raise ValueError(f"{len(labels)} labels for {len(folders)} evaluation folders")
    runs = []
    for k, folder in enumerate(folders):
        path = Path(folder) / "summary.json"
        if not path.exists():
            raise ValueError(f"{folder}: no summary.json yet (an evaluation running or "
                             f"stopped: run its `rmbench eval` again to finish it)"
                             if (Path(folder) / "run.json").exists() else
                             f"{folder}: no summary.json (not an `rmbench eval` folder)")
        summary = read_json_object(path, ("policy", "tasks"))
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
          tasks: list[str] | None = None, with_chance: bool = False, intervals: bool = False,
          published_table: str = "main") -> tuple[list[str], list[list]]:
    """Header and rows: task, TMC, one value (%) of ``metric`` (success_rate or mean_progress)
    per column; None where not evaluated. Published numbers exist for success rates only, and
    so does the last column ``with_chance`` adds: the task's chance level for a policy
    without memory (``eval/chance.py``). ``tasks`` keeps only those rows (default: all nine).
    ``intervals``: success rates are ``Rate``s (floats with their count and interval).
    ``published`` names columns of the paper's ``published_table`` (``main``, ``ablations``:
    ``eval/published.py``); None where it gives a column no number for a task, and its
    average where the paper states one."""
    intervals = intervals and metric == "success_rate"
    published = published if metric == "success_rate" else []
    rates = _published.columns(published_table)
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
            if intervals:
                vals = [Rate.of(r["summary"]["tasks"][t]) if t in r["summary"]["tasks"]
                        else None for r in runs]
                vals += [Rate(rates[p][t], PUBLISHED_ROLLOUTS) if t in rates[p] else None
                         for p in published]
            else:
                vals = [100 * r["summary"]["tasks"][t][metric] if t in r["summary"]["tasks"]
                        else None for r in runs] + [rates[p].get(t) for p in published]
            vals += [100 * chance(t).rate] * with_chance
            group_rows.append([t, group, *vals])
        rows.extend(group_rows)
        rows.append([f"average {group}", group, *_averages(group_rows)])
    task_rows = [r for r in rows if not str(r[0]).startswith("average")]
    rows.append(["average (all)", "", *_averages(task_rows)])
    # an average the paper states (over all of a group's tasks) reads as it states it: 25.25
    # reads its 25.3, not 25.2; one that reads the same keeps its interval
    averages = [r for r in rows if str(r[0]).startswith("average")]
    for row in averages if len(task_rows) == len(ordered()) else []:
        for k, p in enumerate(published):
            given = _published.stated(published_table, p, row[1])
            if given is not None and f"{row[2 + len(runs) + k]:.1f}" != f"{given:.1f}":
                row[2 + len(runs) + k] = given
    return header, rows


def _averages(rows: list[list]) -> list:
    out = []
    for k in range(2, len(rows[0])):
        vals = [r[k] for r in rows]
        if any(v is None for v in vals):
            out.append(None)
        elif all(isinstance(v, Rate) for v in vals) and len({v.episodes for v in vals}) == 1:
            # equal counts: the average is the pooled episodes' rate, with their interval
            out.append(Rate(sum(v.successes for v in vals), sum(v.episodes for v in vals)))
        else:
            out.append(sum(vals) / len(vals))
    return out


def format_cell(v) -> str:
    """'85.0', or '85.0 [77, 91]' for a ``Rate``: the value and its 95% interval."""
    if v is None:
        return "—"
    if isinstance(v, Rate):
        low, high = v.ci95
        return f"{v:.1f} [{low:.0f}, {high:.0f}]"
    return f"{v:.1f}"


def markdown(runs: list[dict], published: list[str]) -> str:
    lines = []
    for metric, title in (("success_rate", "Success rate (%) [95% interval]"),
                          ("mean_progress", "Progress (mean of each episode's best, %)")):
        header, rows = table(runs, published, metric, with_chance=True, intervals=True)
        lines += [f"# {title}", "", "| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
        for r in rows:
            bold = str(r[0]).startswith("average")
            cells = [f"**{r[0]}**" if bold else r[0], r[1]] + [format_cell(v) for v in r[2:]]
            lines.append("| " + " | ".join(cells) + " |")
        lines.append("")
    lines += probe_markdown(runs)
    if published:
        lines += [f"Published: arXiv {published_source()}.", ""]
    lines += ["Runs: " + ", ".join(
        f"{r['name']}: `{r['policy']}` ({r['folder']})" if r["name"] != r["policy"]
        else f"`{r['name']}` ({r['folder']})" for r in runs), ""]
    return "\n".join(lines)


def probe_markdown(runs: list[dict]) -> list[str]:
    """The memory probes the folders hold: per task, the rate with and without the reset, the
    drop (points) and its 95% interval."""
    rows = [(run["name"], t, name, c) for run in runs
            for t, r in run["summary"]["tasks"].items()
            for name, c in r.get("memory_reset", {}).items() if c.get("episodes")]
    if not rows:
        return []
    lines = ["# Memory probe (the policy reset mid-episode, the same seeds)", "",
             "| policy | task | memory reset | episodes | reset in | without | with | "
             "drop (points) [95% interval] | outside the noise |", "|" + "---|" * 9]
    for name, t, probe, c in rows:
        lines.append(f"| {name} | {t} | {probe} | {c['episodes']} | {c['reset_episodes']} | "
                     f"{rate_text(c['without'], c['episodes'])} | "
                     f"{rate_text(c['with'], c['episodes'])} | {drop_text(c)} | "
                     f"{'yes' if c['outside_noise'] else 'no'} |")
    return lines + [""]


def html_report(runs: list[dict], published: list[str]) -> str:
    header, rows = table(runs, published, intervals=True)
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
                   + "".join(f"<td>{format_cell(v)}</td>" for v in r[2:]) + "</tr>")
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
