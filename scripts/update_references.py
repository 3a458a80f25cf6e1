#!/usr/bin/env python3
"""Remake the stored references (validation/<benchmark>/reference/curve.csv)
that tests/stored_references.rs compares against: each reference.toml's
scene is run with its overrides and its curve.csv kept. Run it after a change
that is meant to move a benchmark curve, and say so in the commit.

    cargo build --release && python3 scripts/update_references.py
"""
import shutil
import subprocess
import sys
import tempfile
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
BINARY = ROOT / "target" / "release" / "mpm-geo"


def main():
    if not BINARY.exists():
        sys.exit(f"{BINARY} not found: run `cargo build --release` first")
    for spec_path in sorted((ROOT / "validation").glob("*/reference/reference.toml")):
        spec = tomllib.loads(spec_path.read_text())
        with tempfile.TemporaryDirectory() as out:
            command = [str(BINARY), "run", str(ROOT / "validation" / spec["scene"]),
                       "--out", out, "--overwrite", "--quiet"]
            for override in spec["overrides"]:
                command += ["--set", override]
            print(" ".join(command[1:]), flush=True)
            subprocess.run(command, check=True)
            shutil.copy(Path(out) / "curve.csv", spec_path.parent / "curve.csv")


if __name__ == "__main__":
    main()
