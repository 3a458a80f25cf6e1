#!/usr/bin/env python3
"""Wall time per run and per stage of finished campaigns (issue 15's campaign benchmark).

Reads every `*/run.json` under each campaign output directory given on the command line
and writes, to the directory named by --out:
  timings.csv  one row per run: campaign, run, status, steps, Newton iterations, wall
               seconds, then the seconds of every profile stage (src/profile.rs); the
               number columns named with their unit as mpm-geo's CSV files are
               (`wall_s`, `steps_1`, `p2g_s`);
  timings.md   the same as a Markdown table, with a total per campaign and overall.
With --base ROOT (the output root of a base binary's campaigns of the same
names, as scripts/bench_campaigns.sh writes them), every row also carries the
base run's wall time and the ratio base/new of the wall time and of every stage
(`wall_ratio_1`, `p2g_ratio_1`, ...), and the totals their ratios.
Standard library only.
"""
import argparse
import csv
import json
import pathlib

# the stages of `mpm-geo run`'s profile, in its order (src/profile.rs)
STAGES = ["setup", "p2g", "time_step", "newton", "stress_update", "nonlocal", "assembly",
          "factorisation", "solve", "g2p", "remap", "stresses", "double_mapping", "commit",
          "output", "other"]


def runs_of(campaign_dir):
    for run_json in sorted(pathlib.Path(campaign_dir).glob("*/run.json")):
        record = json.loads(run_json.read_text())
        # "profile": [{"stage": name, "calls": n, "seconds": s}, ...]
        by_stage = {e.get("stage"): e.get("seconds", 0.0) for e in record.get("profile") or []}
        seconds = {f"{stage}_s": float(by_stage.get(stage, 0.0)) for stage in STAGES}
        usage = (record.get("solver") or {}).get("usage") or {}
        yield {
            "campaign": pathlib.Path(campaign_dir).name,
            "run": run_json.parent.name,
            "status": record.get("status", "?"),
            "steps_1": record.get("steps_completed", 0),
            "newton_iterations_1": usage.get("newton_iterations", 0),
            "wall_s": record.get("wall_seconds", 0.0),
            **seconds,
        }


def ratio(base, new):
    """base/new as text, or an empty string where either is missing."""
    return f"{base / new:.2f}" if base and new else ""


def add_base(rows, base_root):
    """The base binary's wall time and the ratios base/new into every row."""
    base = {}
    for campaign in dict.fromkeys(r["campaign"] for r in rows):
        for row in runs_of(pathlib.Path(base_root) / campaign):
            base[(campaign, row["run"])] = row
    for r in rows:
        b = base.get((r["campaign"], r["run"]))
        r["base_status"] = b["status"] if b else "missing"
        r["base_wall_s"] = b["wall_s"] if b else None
        for key in ["wall"] + STAGES:
            r[f"{key}_ratio_1"] = ratio(b[f"{key}_s"], r[f"{key}_s"]) if b else ""


def ratio_table(rows, used):
    """Markdown rows: wall times of both binaries and the ratio of each stage."""
    lines = ["| campaign | run | status (new / base) | wall new (s) | wall base (s) | base/new | "
             + " | ".join(f"{s} base/new" for s in used) + " |",
             "|---|---|---|---|---|---|" + "---|" * len(used)]
    for r in rows:
        base_wall = "" if r["base_wall_s"] is None else f"{r['base_wall_s']:.1f}"
        lines.append(f"| {r['campaign']} | {r['run']} | {r['status']} / {r['base_status']} | "
                     f"{r['wall_s']:.1f} | {base_wall} | {r['wall_ratio_1']} | "
                     + " | ".join(r[f"{s}_ratio_1"] for s in used) + " |")
    return lines


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("campaigns", nargs="+", help="campaign output directories")
    parser.add_argument("--out", required=True, help="directory for timings.csv and timings.md")
    parser.add_argument("--base", help="output root of the base binary's campaigns (same names)")
    args = parser.parse_args()
    rows = [row for c in args.campaigns for row in runs_of(c)]
    if args.base:
        add_base(rows, args.base)
    out = pathlib.Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    columns = ["campaign", "run", "status", "steps_1", "newton_iterations_1", "wall_s"] + [
        f"{stage}_s" for stage in STAGES]
    if args.base:
        columns += ["base_status", "base_wall_s", "wall_ratio_1"] + [
            f"{stage}_ratio_1" for stage in STAGES]
    with open(out / "timings.csv", "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=columns)
        writer.writeheader()
        writer.writerows(rows)
    # the Markdown table leaves out stages that are zero in every run
    used = [s for s in STAGES if any(r[f"{s}_s"] > 0.0005 for r in rows)]
    if args.base:
        lines = ratio_table(rows, used)
    else:
        lines = ["| campaign | run | status | steps | wall (s) | " + " | ".join(used) + " |",
                 "|---|---|---|---|---|" + "---|" * len(used)]
        for r in rows:
            lines.append(f"| {r['campaign']} | {r['run']} | {r['status']} | {r['steps_1']} | "
                         f"{r['wall_s']:.1f} | " + " | ".join(f"{r[s + '_s']:.1f}" for s in used)
                         + " |")
    lines.append("")
    total = base_total = 0.0
    for c in dict.fromkeys(r["campaign"] for r in rows):
        mine = [r for r in rows if r["campaign"] == c]
        wall = sum(r["wall_s"] for r in mine)
        total += wall
        line = f"- {c}: {wall:.0f} s of run wall time ({len(mine)} runs)"
        if args.base:
            base_wall = sum(r["base_wall_s"] or 0.0 for r in mine)
            base_total += base_wall
            line += f"; base {base_wall:.0f} s, ratio base/new {ratio(base_wall, wall)}"
        lines.append(line)
    line = f"- all: {total:.0f} s = {total / 60:.1f} min of run wall time"
    if args.base:
        line += f"; base {base_total / 60:.1f} min, ratio base/new {ratio(base_total, total)}"
    lines.append(line + " (runs in parallel overlap: see the elapsed time per shard in bench.log)")
    (out / "timings.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
