"""An evaluation's ``summary.md``: each task's success rate with its 95% interval, progress
and endings, and each memory probe's rates with and without it."""

from __future__ import annotations

from rmbench.eval.episode import ENDINGS
from rmbench.eval.intervals import format_difference, wilson


def summary_markdown(summary: dict) -> str:
    lines = [f"# {summary['policy']}: evaluation seed {summary['seed']}, "
             f"{summary['instructions']} instructions", "",
             "| task | TMC | episodes | success rate [95% interval] | mean progress | "
             + " | ".join(ENDINGS) + " |",
             "|---|---|---|---|---|" + "---|" * len(ENDINGS)]
    for t, r in summary["tasks"].items():
        lines.append(f"| {t} | {r['tmc']} | {r['episodes']} | {rate_text(r)} | "
                     f"{r['mean_progress']:.3f} | "
                     + " | ".join(str(r["endings"][e]) for e in ENDINGS) + " |")
    probes = [(t, name, c) for t, r in summary["tasks"].items()
              for name, c in r.get("memory_reset", {}).items() if c.get("episodes")]
    if probes:
        lines += ["", "## Memory probe (the policy reset mid-episode, the same seeds)", "",
                  "| task | memory reset | episodes | reset in | without | with | drop (points) "
                  "[95% interval] | outside the noise | lost / gained |",
                  "|---|---|---|---|---|---|---|---|---|"]
        for t, name, c in probes:
            lines.append(f"| {t} | {name} | {c['episodes']} | {c['reset_episodes']} | "
                         f"{rate_text(c['without'], c['episodes'])} | "
                         f"{rate_text(c['with'], c['episodes'])} | {drop_text(c)} | "
                         f"{'yes' if c['outside_noise'] else 'no'} | "
                         f"{c['changed']['lost']} / {c['changed']['gained']} |")
    return "\n".join(lines) + "\n"


def rate_text(r: dict, episodes: int | None = None) -> str:
    """'85.0% [76.7, 90.7]': a summary's success rate and its Wilson 95% interval (computed
    from the count where an older summary lacks it)."""
    n = r.get("episodes", episodes)
    ci = r.get("success_ci95") or (wilson(round(r["success_rate"] * n), n) if n else None)
    rate = f"{100 * r['success_rate']:.1f}%"
    return rate if ci is None else f"{rate} [{100 * ci[0]:.1f}, {100 * ci[1]:.1f}]"


def drop_text(c: dict) -> str:
    return format_difference(c["drop"], *c["drop_ci95"], digits=1)
