"""Write the sample plates of labauto/data/plates/: PNG images and their ground truth as JSON.

Usage: ``python scripts/make_sample_plates.py [OUT_DIR]`` (default: labauto/data/plates).
The plates are deterministic (fixed seeds); the sensor noise is lowered to 0.6 grey levels to keep
the PNGs small (about 1.1 MB each).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import cv2

from labauto.synthetic.plates import generate_plate

#: Sensor noise (grey levels) of the sample plates.
NOISE = 0.6

#: (seed, agar, stage) of every sample plate.
SAMPLES = (
    (101, "amber", "dark"),
    (202, "red_blood", "light"),
    (303, "chocolate", "dark"),
)


def main(argv: list[str] | None = None) -> int:
    """Generate the sample plates into the directory given (or the package's data folder)."""
    args = sys.argv[1:] if argv is None else argv
    root = Path(__file__).resolve().parents[1]
    out = Path(args[0]) if args else root / "labauto" / "data" / "plates"
    out.mkdir(parents=True, exist_ok=True)
    for seed, agar, stage in SAMPLES:
        image, truth = generate_plate(seed, agar=agar, stage=stage, noise_sigma=NOISE)
        stem = f"plate_{seed}_{agar}"
        png = out / f"{stem}.png"
        if not cv2.imwrite(str(png), image, [cv2.IMWRITE_PNG_COMPRESSION, 9]):
            raise OSError(f"could not write {png}")
        data = truth.to_dict()
        data["image"] = png.name
        data["noise_sigma"] = NOISE
        text = json.dumps(data, separators=(",", ":")) + "\n"
        (out / f"{stem}.json").write_text(text, encoding="utf-8")
        print(f"{png}  {truth.counts()}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
