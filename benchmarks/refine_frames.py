"""The local search's first refinement of a search trial, its frames kept, and how many database matches
SIFT finds in them when the images are sharpened first (docs/tuning/search-error-scale-2.md).

    nice .venv/bin/python benchmarks/refine_frames.py grab --sensing realistic --error-scale 2 --seed 9 \
        --object book --surface floor --out out/refine_book9.pkl
    nice .venv/bin/python benchmarks/refine_frames.py matches out/refine_book9.pkl --variants "as is,sharp1.0"

``grab`` runs the ``lab eval search`` trial (paper strategy, no obstacles) until its first refinement
ends and pickles that refinement's frames (the start frame and the refinement frames), the feature
database and the reason the track ended; tuning seeds only. ``matches`` prints, for each frame and each
variant, SIFT's stereo features over the whole image and the matcher's database candidates, as captured
and enlarged twice (``f<k>u<upsample>: features / matches / spread``, the spread the matched database
points' second singular value per point [cm]: near 0, the points lie on a line and an update is
skipped as degenerate). Variants: ``as is``; ``sharpA`` an unsharp mask, ``(1 + A) I - A G_1px * I``;
``deblurS`` the camera's blur stated as S px, whose excess over SIFT's 0.5 px
:func:`lab.vision.stereo.stereo_features` sharpens (``2 I - G_s * I``, ``s = sqrt(S^2 - 0.5^2)``).
"""

from __future__ import annotations

import argparse
import dataclasses
import importlib
import os
import pickle
from pathlib import Path

import numpy as np


class _Grabbed(Exception):
    pass


def grab(out: Path, sensing: str, error_scale: float, seed: int, object: str, surface: str) -> None:
    """Run the trial until its first refinement ends, and pickle that refinement's frames."""
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    from lab.eval.search import SearchSweep
    from lab.evaluation import split_of

    if split_of([seed]) != "tuning":
        raise SystemExit(
            f"seed {seed} is not a tuning seed: this benchmark looks at tuning seeds (below 1000)"
        )
    local = importlib.import_module("lab.search.local_search")  # the module, not the function of that name
    refine = local.refine_track

    def kept(robot, db, matcher, detector, ekf, frame, cfg, upsample=1):
        frames, capture = [frame], robot.capture_stereo

        def capture_kept():
            frames.append(capture())
            return frames[-1]

        robot.capture_stereo = capture_kept
        track = refine(robot, db, matcher, detector, ekf, frame, cfg, upsample)
        robot.capture_stereo = capture
        out.write_bytes(pickle.dumps({"frames": frames, "db": db, "reason": track.reason}))
        print(f"first refinement at {frame.t:.1f} s: {track.reason}; {len(frames)} frames -> {out}")
        raise _Grabbed

    local.refine_track = kept
    sweep = SearchSweep(
        seeds=(seed,),
        strategies=("paper",),
        sensing=(sensing,),
        objects=(object,),
        surfaces=(surface,),
        obstacles="no",
        error_scale=(error_scale,),
    )
    job = sweep.jobs()[0]
    try:
        job.fn(**job.kwargs)
    except _Grabbed:
        return
    print("the trial ended without a refinement")


def _variant(frame, name: str):
    """The frame as the variant ``name`` gives it to SIFT (its camera's stated blur 0 unless ``deblurS``)."""
    import cv2

    frame = dataclasses.replace(frame, camera=dataclasses.replace(frame.camera, blur_sigma_px=0.0))
    if name == "as is":
        return frame
    prefix = "deblur" if name.startswith("deblur") else "sharp"
    try:
        value = float(name.removeprefix(prefix)) if name.startswith(prefix) else -1.0
    except ValueError:
        value = -1.0
    if not value >= 0:
        raise SystemExit(
            f"unknown variant {name!r}: 'as is', sharpA (A a number >= 0, e.g. sharp1.0) or deblurS (S the "
            "camera's blur [px] as stated, e.g. deblur1.0)"
        )
    if prefix == "deblur":
        return dataclasses.replace(frame, camera=dataclasses.replace(frame.camera, blur_sigma_px=value))

    def sharp(img):
        g = cv2.GaussianBlur(img.astype(np.float32), (0, 0), 1.0)
        return np.clip(img.astype(np.float32) * (1.0 + value) - value * g, 0, 255).astype(img.dtype)

    return dataclasses.replace(frame, left=sharp(frame.left), right=sharp(frame.right))


def matches(path: Path, variants: list[str]) -> None:
    """Print the features and database matches of each kept frame under each variant."""
    from lab.search.local_search import make_matcher
    from lab.search.tracking import region_features
    from lab.vision.stereo import sift

    if not path.is_file():
        raise SystemExit(f"refine_frames: no kept refinement at {path}: make one with `grab --out {path}`")
    d = pickle.loads(path.read_bytes())
    matcher = make_matcher(d["db"])
    print(f"{path}: {len(d['frames'])} frames; the track ended: {d['reason']}")
    for v in variants:
        row = []
        for k, fr in enumerate(d["frames"]):
            fr2 = _variant(fr, v)
            for up in (1, 2):
                f, _, _ = region_features(fr2, None, up, sift())
                _, b_O, _ = matcher.match(f).pairs(f, d["db"])
                spread = 0.0
                if len(b_O) >= 3:
                    sv = np.linalg.svd(b_O - b_O.mean(0), compute_uv=False)
                    spread = sv[1] / np.sqrt(len(b_O))
                row.append(f"f{k}u{up}: {len(f.points_C)}/{len(b_O)}/{100 * spread:.1f}")
        print(f"{v:9s} " + "  ".join(row), flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="cmd", required=True)
    g = sub.add_parser("grab")
    g.add_argument("--sensing", default="realistic")
    g.add_argument("--error-scale", type=float, default=1.0)
    g.add_argument("--seed", type=int, required=True)
    g.add_argument("--object", default="book")
    g.add_argument("--surface", default="floor")
    g.add_argument("--out", type=Path, required=True)
    m = sub.add_parser("matches")
    m.add_argument("path", type=Path)
    m.add_argument("--variants", default="as is,sharp0.5,sharp1.0")
    a = ap.parse_args()
    if a.cmd == "grab":
        grab(a.out, a.sensing, a.error_scale, a.seed, a.object, a.surface)
    else:
        matches(a.path, [v.strip() for v in a.variants.split(",")])


if __name__ == "__main__":
    main()
