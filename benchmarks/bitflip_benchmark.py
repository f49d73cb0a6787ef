"""Bit flips in a bag, replayed: is every damaged byte refused, or without effect?

Flips ``--flips`` seeded random bits (one per run) of a bag's MCAP file (default: the bundled
``bags/t2_maneuver``), replays each damaged copy with ``rls-uncertainty replay --config t2``
in a process of its own, and sorts the outcome:

* ``refused``: the replay exits non-zero (its one-line error is shown);
* ``unchanged``: it exits 0 and writes the same ``estimates.csv`` as the undamaged bag;
* ``changed``: it exits 0 with other numbers: the damage went unnoticed (the largest relative
  change of a final estimate is shown).

Each flip is located in the file's record structure (the MCAP record it falls in: header,
chunk i, message index, metadata, summary, footer, magic). A bag written with chunk, data
section and summary CRCs should give no ``changed`` row. Figures: docs/tools.md (integrity).

    .venv/bin/python benchmarks/bitflip_benchmark.py [--flips 40] [--seed 19] [--bag DIR]

To measure another checkout's code and bag, run this script from this checkout with that
checkout first on the path: ``PYTHONPATH=/path/to/other .venv/bin/python
benchmarks/bitflip_benchmark.py --bag /path/to/other/bags/t2_maneuver``.
"""

from __future__ import annotations

import argparse
import csv
import os
import random
import shutil
import struct
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
_MAGIC = 8
_OPCODES = {0x01: "header", 0x02: "footer", 0x03: "schema", 0x04: "channel", 0x05: "message", 0x06: "chunk",
            0x07: "message index", 0x08: "chunk index", 0x09: "attachment", 0x0A: "attachment index",
            0x0B: "statistics", 0x0C: "metadata", 0x0D: "metadata index", 0x0E: "summary offset",
            0x0F: "data end"}


def regions(data: bytes) -> list[tuple[int, int, str]]:
    """``(start, end, label)`` of every top-level record of an MCAP file, and its two magics.
    A chunk is labelled with its ordinal (``chunk 1``...)."""
    out = [(0, _MAGIC, "leading magic")]
    pos, chunks = _MAGIC, 0
    while pos < len(data) - _MAGIC:
        opcode = data[pos]
        (length,) = struct.unpack_from("<Q", data, pos + 1)
        label = _OPCODES.get(opcode, f"opcode {opcode:#04x}")
        if opcode == 0x06:
            chunks += 1
            label = f"chunk {chunks}"
        out.append((pos, pos + 9 + length, label))
        pos += 9 + length
    out.append((len(data) - _MAGIC, len(data), "trailing magic"))
    return out


def where(offset: int, layout: list[tuple[int, int, str]]) -> str:
    for start, end, label in layout:
        if start <= offset < end:
            part = "record header" if offset < start + 9 and "magic" not in label else ""
            return f"{label} ({part})" if part else label
    return "?"


def replay(bag: Path, out: Path) -> tuple[int, str]:
    """Exit status and the last line of stderr of a replay of ``bag`` into ``out``."""
    cmd = [sys.executable, "-m", "rls_uncertainty.cli", "replay", str(bag), "--config", "t2", "--out", str(out),
           "--no-figures", "--quiet"]
    try:
        proc = subprocess.run(cmd, check=False, capture_output=True, text=True, timeout=300, env=dict(os.environ))
    except subprocess.TimeoutExpired:
        return -1, "timed out after 300 s"
    lines = [line for line in proc.stderr.splitlines() if line.strip()]
    return proc.returncode, lines[-1] if lines else ""


def final_estimates(csv_path: Path) -> dict[tuple[str, str], float]:
    """The last estimate of every (model, parameter) in a replay's estimates.csv."""
    last: dict[tuple[str, str], float] = {}
    with open(csv_path, newline="") as fh:
        for row in csv.DictReader(fh):
            last[row["model"], row["parameter"]] = float(row["estimate"])
    return last


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--bag", type=Path, default=ROOT / "bags" / "t2_maneuver")
    ap.add_argument("--flips", type=int, default=40)
    ap.add_argument("--seed", type=int, default=19)
    args = ap.parse_args()
    (mcap,) = sorted(args.bag.glob("*.mcap"))
    clean = mcap.read_bytes()
    layout = regions(clean)
    rng = random.Random(args.seed)
    counts = {"refused": 0, "unchanged": 0, "changed": 0}
    with tempfile.TemporaryDirectory(prefix="bitflip_") as tmp:
        code, err = replay(args.bag, Path(tmp) / "clean")
        if code != 0:
            print(f"the undamaged bag does not replay (exit {code}): {err}", file=sys.stderr)
            return 1
        reference = (Path(tmp) / "clean" / "estimates.csv").read_bytes()
        final = final_estimates(Path(tmp) / "clean" / "estimates.csv")
        print(f"{args.bag}: {len(clean)} bytes, {args.flips} single-bit flips (seed {args.seed})")
        print(f"{'#':>3} {'byte':>8} {'bit':>3}  {'where':<28} outcome")
        for i in range(args.flips):
            bit = rng.randrange(8 * len(clean))
            offset = bit // 8
            damaged = bytearray(clean)
            damaged[offset] ^= 1 << (bit % 8)
            bag = Path(tmp) / f"flip{i}"
            shutil.copytree(args.bag, bag)
            (bag / mcap.name).write_bytes(bytes(damaged))
            code, err = replay(bag, Path(tmp) / f"out{i}")
            out_csv = Path(tmp) / f"out{i}" / "estimates.csv"
            if code != 0:
                kind, text = "refused", f"exit {code}: {err[:160]}"
            elif out_csv.read_bytes() == reference:
                kind, text = "unchanged", "exit 0, same estimates.csv"
            else:
                got = final_estimates(out_csv)
                worst = max((abs(got.get(k, float("nan")) - v) / max(abs(v), 1e-300) for k, v in final.items()),
                            default=float("nan"))
                kind, text = "changed", f"exit 0, final estimates changed by up to {100 * worst:.3g} %"
            counts[kind] += 1
            print(f"{i + 1:>3} {offset:>8} {bit % 8:>3}  {where(offset, layout):<28} {kind}: {text}", flush=True)
            shutil.rmtree(bag)
            shutil.rmtree(Path(tmp) / f"out{i}", ignore_errors=True)
    print(f"refused {counts['refused']}, unchanged {counts['unchanged']}, changed {counts['changed']} "
          f"(of {args.flips})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
