"""The report's Jinja2 templates (``bench/templates/*.j2``, packaged data).

``report.md`` and ``report.html`` come from the same template,
``report.md.j2``, with a format switch ``html``: the HTML build renders it as
Markdown with a placeholder for the interactive figures, then converts it
(:mod:`bench.report.html`). One Markdown source keeps report.md readable on
GitHub and the HTML identical in content (docs/architecture.md, 'Report').
"""

from __future__ import annotations

import functools

import numpy as np
import pandas as pd

from radarbench.bench.markdown import code, fmt, fmt_db, table, text
from radarbench.bench.metrics import RELATIVE_RESOLUTION


@functools.lru_cache(maxsize=1)
def sentence_case(text: str) -> str:
    """``text`` with its first letter upper case, the rest as written ("CFAR detectors" stays)."""
    return text[:1].upper() + text[1:]


def environment():
    import jinja2
    # HTML templates escape every value; Markdown ones take Markdown (text not ours escaped
    # by the code/text filters or before, bench.markdown)
    env = jinja2.Environment(loader=jinja2.PackageLoader("radarbench.bench", "templates"),
                             autoescape=jinja2.select_autoescape(enabled_extensions=("html.j2",),
                                                                 default_for_string=False),
                             keep_trailing_newline=True, trim_blocks=True, lstrip_blocks=True,
                             undefined=jinja2.StrictUndefined)
    env.filters.update(fmt=fmt, db=fmt_db, pct=percent, code=code, text=text)
    # the ties' definition, stated where ties are named ("1e-9": no "-0" to read as a negative zero)
    env.globals["resolution"] = f"{RELATIVE_RESOLUTION:.0e}".replace("e-0", "e-")
    return env


def percent(x) -> str:
    """A proportion as a percentage, 3 significant digits ("–" when missing)."""
    text = fmt(None if x is None else 100.0 * float(x))
    return text if text == "–" else f"{text}%"


def render(name: str, **values) -> str:
    """Template ``name`` (in bench/templates) rendered with ``values``, blank-line runs collapsed."""
    text = environment().get_template(name).render(**values)
    while "\n\n\n" in text:
        text = text.replace("\n\n\n", "\n\n")
    return text.strip("\n")


def section_macro(name: str):
    """The macro ``name`` of ``sections.md.j2`` (the harness's own sections), as a function."""
    return getattr(environment().get_template("sections.md.j2").module, name)


def _interval(mid, low, high, signed: bool = False) -> str:
    """``mid [low, high]``; an interval that collapsed (every trial equal, in each SNR level,
    so the bootstrap has nothing to resample) says so rather than posing as a precise one:
    "all trials equal: 0.167", or for a difference "+0.1 on every trial"."""
    f = (lambda x: ("+" if signed and np.isfinite(x) and x > 0 else "") + fmt(x))
    if not (np.isfinite(mid) or np.isfinite(low) or np.isfinite(high)):
        return "–"
    if np.isfinite(low) and low == high:
        return f"{f(mid)} on every trial" if signed else f"all trials equal: {f(mid)}"
    return f"{f(mid)} [{f(low)}, {f(high)}]"


def _p(p) -> str:
    return "" if p is None or not np.isfinite(p) else fmt(float(p), 2)


def glance_markdown(entries: list[dict]) -> str:
    """The *Results at a glance* section (``glance.md.j2``)."""
    if not entries:
        return ""
    view = []
    for g in entries:
        task = g["task"]
        show_chance = task.ranking_binary and any(np.isfinite(r["chance"]) for r in g["ranking"])
        label = task.equal_chance_label if g["equal_chance"] else task.ranking_label
        header = ["rank", "config", f"{label} [95% CI]"] + \
            ([f"{task.ranking_label} (any alarm) [95% CI]"] if g["equal_chance"] else []) + \
            ([f"chance Pd{' (any alarm)' if g['equal_chance'] else ''}"] if show_chance else [])
        rows = [["–" if r["unranked"] else str(i), code(r["config"]), _interval(r["mean"], r["low"], r["high"])] +
                ([_interval(*r["secondary"])] if g["equal_chance"] else []) +
                ([fmt(r["chance"])] if show_chance else []) for i, r in enumerate(g["ranking"], start=1)]
        margin = g["margin"]
        if margin is not None:
            margin = {"text": _interval(margin["difference"], margin["low"], margin["high"], signed=True),
                      "tie": margin["tie"], "p": _p(margin["mcnemar_p"]), "enough": margin["enough"],
                      "same": margin["low"] == margin["high"] == 0}
        not_ranked = "; ".join(f"{code(r['config'])} ({text(r['unranked'])})" for r in g["ranking"] if r["unranked"])
        view.append({**g, "margin": margin, "label": label, "table": table(header, rows), "not_ranked": not_ranked})
    return render("glance.md.j2", entries=view, any_binary=any(g["task"].ranking_binary for g in entries),
                  any_equal_chance=any(g["equal_chance"] for g in entries))


def _better(r) -> str:
    """The *better* cell of a comparison row: the config, a tie, or no comparison at all
    (no trial where both have the metric: it is not defined on the scene)."""
    if r.n_pairs == 0:
        return "not defined"
    if getattr(r, "degenerate", "") == "identical":
        return "identical on every trial"
    return "**tie**" if r.better == "tie" else code(r.better)


#: Above this many pairs, a scenario config's comparison table is folded (<details>).
FOLD_PAIRS = 6


def comparisons_markdown(comparisons: pd.DataFrame, task_of: dict) -> str:
    """The *Paired comparisons* section (``comparisons.md.j2``): the all-level rows."""
    overall = comparisons[comparisons.snr_db.isna()]
    if overall.empty:
        return ""
    tasks = {t.name: t for t in task_of.values()}
    blocks = []
    for (scenario, name, metric), g in overall.groupby(["scenario", "task", "metric"], sort=False):
        task = tasks[name]
        fair = metric == task.equal_chance_metric              # a 0/1 outcome at equal chance Pd
        binary = task.ranking_binary or fair
        header = ["a", "b", f"mean a", f"mean b", "b − a [95% CI]"] + \
            (["a only", "b only", "McNemar p"] if binary else []) + ["better"]
        rows = [[code(r.config_a), code(r.config_b), fmt(r.mean_a), fmt(r.mean_b),
                 _interval(r.difference, r.difference_low, r.difference_high, signed=True)] +
                ([str(int(r.only_a)), str(int(r.only_b)), _p(r.mcnemar_p)] if binary else []) +
                [_better(r)] for r in g.itertuples()]
        label = task.equal_chance_label if fair else task.ranking_label
        blocks.append({"caption": f"{sentence_case(task.noun)} on {code(scenario)}: {label} "
                                  f"({'higher' if task.ranking_higher_is_better else 'lower'} is better).",
                       "table": table(header, rows), "pairs": len(rows), "folded": len(rows) > FOLD_PAIRS})
    return render("comparisons.md.j2", blocks=blocks,
                  any_binary=any(tasks[n].ranking_binary for n in overall.task.unique()))
