#!/usr/bin/env python3
"""An approximation's change of every campaign metric against the discretisation error and
against round-off (issue 43's rule for defaults).

    python3 scripts/approximation_rule.py DEFAULT APPROX [--round-off TWIN ...] [--out FILE]

DEFAULT, APPROX and each TWIN are campaign output directories of the same scenes (each holds
the campaign's metrics.csv): DEFAULT with the scenes as written, APPROX with the
approximation's option set (`mpm-geo campaign DIR --set ...`), a TWIN with a change that
alters only round-off (an exact linear solver for another, `--set
'solver.linear_solver="lu"'`; a parameter moved by 1e-12 of itself).

Per family (and integrator, for the cut) the discretisation error of a metric is its gap
between the two finest completed meshes of DEFAULT, |x(h_1) - x(h_2)|. For every run and
paper metric the table gives the approximation's change |x_APPROX - x_DEFAULT|, that change
in units of the gap, and the largest change of any TWIN (the round-off spread). The verdict:
  rule       the change is at most a tenth of the gap (the rule for a default);
  round-off  it is not, but the round-off spread is as large: a change that round-off alone
             makes, so no approximation can meet the rule on that metric;
  fails      neither;
  -          the metric is missing in a run, or the family has a single completed mesh.
Writes the Markdown table to FILE (default: stdout) and, last, the count of each verdict.
Standard library only.
"""
import argparse
import csv
import math
import pathlib
import sys

# the paper's metrics of the campaigns' metrics.csv (src/campaign): biaxial and footing,
# then the vertical cut
METRICS = [
    "peak_load_kN_per_m", "peak_delta_m", "final_load_kN_per_m", "M1_discrepancy_1",
    "M3_brittleness_1", "M3_half_peak_drop_m", "M4_band_width_m", "M4_band_width_kappa_bar_m",
    "M5_dissipation_kJ_per_m", "soil_inside_footing_m2_per_m", "corner_band_reach_left_1",
    "corner_band_reach_right_1",
    "onset_time_s", "uA_at_0.3_m", "uA_final_m", "run_out_final_m", "qB_peak_kPa",
    "qB_fall_roughness_1", "qB_neighbourhood_fall_roughness_1",
]


def read_metrics(campaign_dir):
    """{run: row} of a campaign's metrics.csv."""
    path = pathlib.Path(campaign_dir) / "metrics.csv"
    if not path.is_file():
        sys.exit(f"approximation_rule: no metrics.csv in {campaign_dir} (a finished campaign?)")
    with open(path, newline="") as f:
        return {row["run"]: row for row in csv.DictReader(f)}


def number(row, column):
    """The column's value as a float, or None where missing or not finite."""
    try:
        value = float((row or {}).get(column, ""))
    except ValueError:
        return None
    return value if math.isfinite(value) else None


def group(row):
    """The runs a mesh gap is taken over: one family and integrator."""
    return (row.get("family", ""), row.get("integrator", ""))


def mesh_gaps(default):
    """{(group, metric): |x(h_1) - x(h_2)|} over the two finest completed meshes."""
    by_group = {}
    for row in default.values():
        size = number(row, "cell_size_m")
        if row.get("status") == "completed" and size is not None:
            by_group.setdefault(group(row), []).append((size, row))
    gaps = {}
    for key, sized in by_group.items():
        if len(sized) < 2:
            continue
        (_, finest), (_, second) = sorted(sized, key=lambda s: s[0])[:2]
        for metric in METRICS:
            a, b = number(finest, metric), number(second, metric)
            if a is not None and b is not None:
                gaps[(key, metric)] = abs(a - b)
    return gaps


def verdict(change, gap, spread):
    if change is None or gap is None:
        return "-"
    if change <= 0.1 * gap:
        return "rule"
    if spread is not None and change <= spread:
        return "round-off"
    return "fails"


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("default", help="campaign output of the scenes as written")
    parser.add_argument("approx", help="campaign output with the approximation")
    parser.add_argument("--round-off", action="append", default=[], metavar="TWIN",
                        help="campaign output of a round-off-only change (repeatable)")
    parser.add_argument("--out", help="Markdown file (default: stdout)")
    args = parser.parse_args()
    default, approx = read_metrics(args.default), read_metrics(args.approx)
    twins = [read_metrics(t) for t in args.round_off]
    gaps = mesh_gaps(default)
    lines = ["| run | metric | default | change | change / gap | round-off spread | verdict |",
             "|---|---|---|---|---|---|---|"]
    counts = {}
    for run, row in default.items():
        for metric in METRICS:
            x = number(row, metric)
            if x is None:
                continue
            y = number(approx.get(run), metric)
            change = None if y is None else abs(y - x)
            gap = gaps.get((group(row), metric))
            spreads = [abs(v - x) for v in (number(t.get(run), metric) for t in twins)
                       if v is not None]
            spread = max(spreads) if spreads else None
            said = verdict(change, gap, spread)
            counts[said] = counts.get(said, 0) + 1
            cells = [run, metric, f"{x:.6g}",
                     "-" if change is None else f"{change:.3g}",
                     "-" if change is None or not gap else f"{change / gap:.3g}",
                     "-" if spread is None else f"{spread:.3g}", said]
            lines.append("| " + " | ".join(cells) + " |")
    lines.append("")
    lines.append("verdicts: " + ", ".join(f"{k} {v}" for k, v in sorted(counts.items())))
    text = "\n".join(lines) + "\n"
    if args.out:
        pathlib.Path(args.out).write_text(text)
    sys.stdout.write(text)


if __name__ == "__main__":
    main()
