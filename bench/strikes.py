"""Strikes found against strikes labelled by hand: precision and recall over the 33 shared clips.

The labels (``tests/data/strikes.json``) were made by looking at every clip: a limb unfolding to
near full reach away from the body and stopping there, not part of a gait (issue 25). A found
strike matches a label of the same limb whose frame of full reach lies in the strike's hold (from
the frame it arrives to the last it stays within 0.04 of its top reach), give or take 0.15 s;
"maybe" labels (slashes that do not stop, borderline reaches) are neither required nor counted
against the finder. Prints each clip's strikes found, missed and extra, then the totals.

Not a test: run it by hand (``python bench/strikes.py``) and quote the figures;
``tests/test_strikes.py`` holds the finder to them.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from common import FPS, ROOT, SHARED, settings_table

from mocap_exaggerate import load_bvh
from mocap_exaggerate.analysis.limbs import find_limbs
from mocap_exaggerate.config import PipelineConfig
from mocap_exaggerate.stages.stretch import find_strikes, weigh_strikes

LABELS = ROOT / "tests" / "data" / "strikes.json"
#: How far (seconds) a found strike's frame of full reach may be from the label's.
TOLERANCE = 0.15


def match(found: list[tuple[str, int, int]], strikes: list, maybe: list, frame_time: float) -> dict:
    """Found (limb, arrive, last) holds against the labels: hits, misses, extras (a maybe is neither)."""
    tolerance = TOLERANCE / frame_time
    left = [tuple(s[:2]) for s in strikes]
    hits, extra = [], []
    for limb, arrive, last in found:
        def inside(label, limb=limb, arrive=arrive, last=last):
            return label[0] == limb and arrive - tolerance <= label[1] <= last + tolerance

        near = [s for s in left if inside(s)]
        if near:
            left.remove(min(near, key=lambda s: abs(s[1] - arrive)))
            hits.append((limb, arrive))
        elif not any(inside(m) for m in maybe):
            extra.append((limb, arrive))
    return {"hits": hits, "missed": left, "extra": extra}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", type=Path, default=None, help="also write every figure here")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                        help="an auto_stretch setting, e.g. auto_stretch.min_angle=35 (repeatable)")
    args = parser.parse_args()
    table = settings_table(args.set)
    config = PipelineConfig.from_dict({"auto_stretch": {**table.get("auto_stretch", {}), "enabled": True}},
                                      source="--set").auto_stretch
    labels = json.loads(LABELS.read_text())["clips"]
    totals = {"hits": 0, "missed": 0, "extra": 0, "labels": 0}
    rows = {}
    print("| clip | labelled | found | missed | extra |\n|---|---|---|---|---|")
    for name, label in labels.items():
        path = SHARED / name if (SHARED / name).exists() else SHARED / "wide" / name
        if not path.exists():
            sys.exit(f"{path}: not found (the labels name the clips of ../shared/data/bvh and its wide/)")
        motion = load_bvh(path, fps=FPS.get(name))
        limbs = find_limbs(motion.skeleton)
        weighed = weigh_strikes(motion.world_positions(), motion.skeleton, limbs, motion.frame_time, config)
        found = find_strikes(None, motion.skeleton, limbs, motion.frame_time, config, weighed)
        holds = {(c.limb, c.arrive): c.last for c in weighed}
        got = match([(s.limb, int(s.end), holds[s.limb, int(s.end)]) for s in found], label["strikes"], label["maybe"],
                    motion.frame_time)
        rows[name] = got
        for key in ("hits", "missed", "extra"):
            totals[key] += len(got[key])
        totals["labels"] += len(label["strikes"])
        if label["strikes"] or found:
            print(f"| {name.removesuffix('.bvh')} | {len(label['strikes'])} | {len(got['hits'])} "
                  f"| {' '.join(f'{limb}@{f}' for limb, f in got['missed']) or '-'} "
                  f"| {' '.join(f'{limb}@{f}' for limb, f in got['extra']) or '-'} |")
    found_total = totals["hits"] + totals["extra"]
    precision = totals["hits"] / found_total if found_total else 1.0
    recall = totals["hits"] / totals["labels"] if totals["labels"] else 1.0
    print(f"\n{totals['labels']} strikes labelled in {len(labels)} clips; found {found_total}: "
          f"precision {precision:.1%}, recall {recall:.1%} ({totals['missed']} missed, {totals['extra']} extra)")
    if args.json:
        args.json.write_text(json.dumps({"totals": totals, "precision": precision, "recall": recall,
                                         "clips": rows}, indent=1) + "\n")


if __name__ == "__main__":
    main()
