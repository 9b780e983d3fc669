"""Make this folder's crop of EMVA1288_ReferenceSet_001_CCD_12Bit (github.com/EMVA1288/datasets).

    python test/data/emva1288_ccd/crop.py PATH/EMVA1288_ReferenceSet_001_CCD_12Bit test/data/emva1288_ccd

Keeps every other exposure level of the temporal series (pairs), the first 8 images of each spatial set,
the 64 x 64 pixels at the sensor's centre, and writes the descriptor for them (exposures and photon counts
unchanged). The codes are copied as they are (16-bit PNG).
"""
from __future__ import annotations

import sys
from pathlib import Path

import cv2

SIZE = 64
SPATIAL = 8


def main(src: Path, dst: Path) -> None:
    lines = (src / "EMVA1288_Data.txt").read_text().splitlines()
    header = [ln for ln in lines if ln.startswith("#") or ln.split()[:1] in (["v"], ["n"])]
    blocks: list[tuple[str, list[str]]] = []
    for ln in lines:
        key = ln.split()[:1]
        if key in (["b"], ["d"]):
            blocks.append((ln, []))
        elif key == ["i"]:
            blocks[-1][1].append(ln.split(None, 1)[1].replace("\\", "/"))
    out = [ln if not ln.startswith("n ") else f"n {ln.split()[1]} {SIZE} {SIZE}" for ln in header]
    out.insert(0, "# A 64 x 64 crop of EMVA1288_ReferenceSet_001_CCD_12Bit made by crop.py (see README.md)")
    level = {"b": 0, "d": 0}
    (dst / "images").mkdir(parents=True, exist_ok=True)
    for head, files in blocks:
        kind = head[0]
        if len(files) == 2:
            level[kind] += 1
            if level[kind] % 2 == 0:
                continue
        else:
            files = files[:SPATIAL]
        out.append(head)
        for f in files:
            img = cv2.imread(str(src / f), cv2.IMREAD_UNCHANGED)
            h, w = img.shape
            crop = img[(h - SIZE) // 2:(h + SIZE) // 2, (w - SIZE) // 2:(w + SIZE) // 2]
            cv2.imwrite(str(dst / "images" / Path(f).name), crop)
            out.append(f"i images\\{Path(f).name}")
    (dst / "EMVA1288_Data.txt").write_text("\n".join(out) + "\n")


if __name__ == "__main__":
    main(Path(sys.argv[1]), Path(sys.argv[2]))
