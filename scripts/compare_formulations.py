#!/usr/bin/env python3
"""Our formulation beside the paper's literal one, run by run (issue 12).

    mpm-geo campaign validation/footing --out runs/footing
    mpm-geo campaign validation/footing --formulation paper --out runs/footing-paper
    python3 scripts/compare_formulations.py runs/footing runs/footing-paper > compare.md

Reads the `metrics.csv` of both campaign directories (written by `mpm-geo campaign`),
pairs the runs by name and writes a Markdown table: for every metric of the benchmark,
ours / the paper's. A run missing on one side (not finished yet) shows "–". The
benchmark is told by the columns: the vertical cut's onset and run-out, a filled
corner-band reach for the footing, else a load-curve campaign (the biaxial test).
Standard library only.
"""
import argparse
import csv
import pathlib

# (column of metrics.csv, heading, format) per benchmark
CUT = [("status", "status", "{}"), ("onset_time_s", "onset (s)", "{:.4f}"),
       ("uA_at_0.3_m", "u_A(0.3 s) (m)", "{:.3f}"), ("uA_final_m", "u_A(1 s) (m)", "{:.2f}"),
       ("run_out_final_m", "run-out (m)", "{:.2f}"),
       ("qB_fall_roughness_1", "q_B roughness", "{:.2f}"), ("M1_discrepancy_1", "M1", "{:.4f}")]
LOAD_CURVE = [("status", "status", "{}"), ("peak_load_kN_per_m", "peak", "{:.4g}"),
              ("peak_delta_m", "δ at peak", "{:.4g}"), ("final_load_kN_per_m", "final load", "{:.4g}"),
              ("M1_discrepancy_1", "M1", "{:.4f}"), ("M2_peak_spread_1", "M2", "{:.4f}"),
              ("M4_band_width_m", "band width (m)", "{:.4g}")]
FOOTING = LOAD_CURVE + [("corner_band_reach_left_1", "corner reach L (B)", "{:.2f}"),
                        ("corner_band_reach_right_1", "corner reach R (B)", "{:.2f}"),
                        ("soil_inside_footing_m2_per_m", "soil inside (m²/m)", "{:.3f}")]
# units that end a column name (src/csv_columns.rs); the campaigns stored in
# docs/results predate them: their columns are the names without the unit
UNITS = ["kN_per_m2", "kN_per_m", "kJ_per_m", "m2_per_m", "kPa", "m", "s", "1"]


def without_unit(column):
    """The column's name before units were added (`peak_load_kN_per_m` → `peak_load`)."""
    for unit in UNITS:
        if column.endswith("_" + unit):
            return column[: -len(unit) - 1]
    return column


def read(directory):
    path = pathlib.Path(directory) / "metrics.csv"
    if not path.is_file():
        raise SystemExit(f"error: {path} does not exist: a campaign writes it once all its runs are done "
                         f"(`mpm-geo campaign DIR --out {directory} --collect` writes it again from them)")
    with path.open(newline="") as f:
        rows = list(csv.DictReader(f))
    return {row["run"]: row for row in rows}, (rows[0].keys() if rows else [])


def cell(row, column, fmt):
    if row is not None and column not in row:
        column = without_unit(column)
    if row is None or row.get(column) in (None, "", "–"):
        return "–"
    value = row[column]
    try:
        return fmt.format(float(value)) if fmt != "{}" else value
    except ValueError:
        return value


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("ours", help="campaign directory of the scenes as written")
    parser.add_argument("paper", help="campaign directory of --formulation paper")
    args = parser.parse_args()
    ours, columns = read(args.ours)
    paper, paper_columns = read(args.paper)
    columns = set(columns) | set(paper_columns)
    rows = list(ours.values()) + list(paper.values())
    # every campaign writes the footing's columns; only a footing campaign fills them
    footing = any(cell(row, "corner_band_reach_left_1", "{}") != "–" for row in rows)
    table = CUT if {"onset_time_s", "onset_time"} & columns else FOOTING if footing else LOAD_CURVE
    print(f"Ours ({args.ours}) / the paper's literal formulation ({args.paper}).\n")
    print("| run | " + " | ".join(heading for _, heading, _ in table) + " |")
    print("|---|" + "---|" * len(table))
    for name in sorted(set(ours) | set(paper)):
        cells = [f"{cell(ours.get(name), c, fmt)} / {cell(paper.get(name), c, fmt)}"
                 for c, _, fmt in table]
        print(f"| {name} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
