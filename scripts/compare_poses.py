#!/usr/bin/env python3
"""Camera poses of a COLMAP model against a reference, after a similarity fit: the figures of
docs/POSE.md ("registered", "median rotation error", "median position error, % of extent").

    compare_poses.py MODEL --reference REF [--reference PREFIX=REF2 …]
                     [--fit NAMES] [--eval NAMES] [--via MODEL2] [--extent points|cameras]

- The similarity (Umeyama, least squares on camera centres) takes MODEL to the reference; it is
  fitted on the `--fit` photos (default: every shared photo) and the errors are given on the
  `--eval` photos (default: the same). NAMES: comma-separated names, or `@file` with one a line,
  or `glob:PATTERN`.
- `--reference PREFIX=REF2`: REF2's photos enter the reference with PREFIX before their names
  (a second survey whose photos were renamed to keep names unique).
- `--via MODEL2`: MODEL is first brought into MODEL2's frame through the `--fit` photos both
  share (the twin's `--align joint`), then MODEL2 to the reference through the `--fit` photos;
  errors on `--eval`. Without it the chain is MODEL to the reference directly.
- `--rotation-fit`: the similarity's rotation from the cameras' orientations (their mean
  offset), scale and shift from the centres; default: Umeyama on centres alone.
- extent: the diagonal of the reference cameras' bounding box (`cameras`, lund), of its 3D
  points' (`points`), or a number (the demo building's diagonal: 16 × 9 × 9.6 m, 20.72).

Needs numpy and pycolmap (to read .bin or .txt models).
"""

import argparse
import fnmatch
import sys

import numpy as np
import pycolmap


def poses(path, prefix=""):
    """name -> (world-to-camera rotation 3x3, camera centre), and the 3D points."""
    model = pycolmap.Reconstruction(path)
    out = {}
    for image in model.images.values():
        if not image.has_pose:
            continue
        pose = image.cam_from_world()
        rotation = pose.rotation.matrix()
        centre = -rotation.T @ pose.translation
        out[prefix + image.name] = (rotation, centre)
    points = np.array([p.xyz for p in model.points3D.values()]).reshape(-1, 3)
    return out, points


def umeyama(src, dst):
    """s, R, t with dst ~ s R src + t (least squares)."""
    mu_s, mu_d = src.mean(0), dst.mean(0)
    a, b = src - mu_s, dst - mu_d
    cov = b.T @ a / len(src)
    u, d, vt = np.linalg.svd(cov)
    sign = np.eye(3)
    if np.linalg.det(u) * np.linalg.det(vt) < 0:
        sign[2, 2] = -1
    rotation = u @ sign @ vt
    scale = np.trace(np.diag(d) @ sign) / (a**2).sum(1).mean()
    return scale, rotation, mu_d - scale * rotation @ mu_s


def apply(sim, cams):
    """Cameras moved by the similarity: centre s R c + t, world-to-camera rotation R_c R^T."""
    s, r, t = sim
    return {n: (rc @ r.T, s * r @ c + t) for n, (rc, c) in cams.items()}


def fit(cams, target, names, rotations=False):
    shared = [n for n in names if n in cams and n in target]
    if len(shared) < 3:
        sys.exit(f"only {len(shared)} photos shared to fit a similarity on")
    src = np.array([cams[n][1] for n in shared])
    dst = np.array([target[n][1] for n in shared])
    if not rotations:
        return umeyama(src, dst)
    # The rotation from the cameras' orientations (the chordal mean of R_ref^T R_model), then
    # scale and shift from the centres: cameras along one street leave the roll about it to
    # the centres' noise in a centre-only fit.
    u, _, vt = np.linalg.svd(sum(target[n][0].T @ cams[n][0] for n in shared))
    rotation = u @ np.diag([1, 1, np.linalg.det(u @ vt)]) @ vt
    a, b = src - src.mean(0), dst - dst.mean(0)
    scale = (b * (a @ rotation.T)).sum() / (a**2).sum()
    return scale, rotation, dst.mean(0) - scale * rotation @ src.mean(0)


def select(spec, universe):
    if spec is None:
        return sorted(universe)
    if spec.startswith("@"):
        with open(spec[1:], encoding="utf-8") as f:
            return [line.strip() for line in f if line.strip()]
    if spec.startswith("glob:"):
        return sorted(n for n in universe if fnmatch.fnmatch(n, spec[5:]))
    return spec.split(",")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("model")
    parser.add_argument("--reference", action="append", required=True)
    parser.add_argument("--fit")
    parser.add_argument("--eval")
    parser.add_argument("--via")
    parser.add_argument("--extent", default="cameras")
    parser.add_argument("--rotation-fit", action="store_true",
                        help="the similarity's rotation from the cameras' orientations")
    args = parser.parse_args()

    reference, ref_points = {}, []
    for spec in args.reference:
        prefix, _, path = spec.rpartition("=")
        cams, points = poses(path, prefix)
        reference.update(cams)
        ref_points.append(points)
    model, _ = poses(args.model)
    fit_names = select(args.fit, set(model) & set(reference))
    eval_names = select(args.eval, set(model) | set(reference))

    if args.via:
        via, _ = poses(args.via)
        model = apply(fit(model, via, fit_names, args.rotation_fit), model)
        model = apply(fit(via, reference, fit_names, args.rotation_fit), model)
    else:
        model = apply(fit(model, reference, fit_names, args.rotation_fit), model)

    if args.extent not in ("cameras", "points"):
        extent = float(args.extent)
    else:
        if args.extent == "points":
            pts = np.concatenate(ref_points)
        else:
            pts = np.array([c for _, c in reference.values()])
        extent = float(np.linalg.norm(pts.max(0) - pts.min(0)))

    rot, pos, missing = [], [], []
    for name in eval_names:
        if name not in reference:
            continue
        if name not in model:
            missing.append(name)
            continue
        (r_m, c_m), (r_r, c_r) = model[name], reference[name]
        cos = (np.trace(r_m @ r_r.T) - 1) / 2
        rot.append(np.degrees(np.arccos(np.clip(cos, -1, 1))))
        pos.append(np.linalg.norm(c_m - c_r) / extent * 100)
    in_reference = sum(1 for n in eval_names if n in reference)
    print(f"registered {len(rot)} of the {in_reference} reference photos evaluated "
          f"(missing: {', '.join(missing) or 'none'}); fit on {len(fit_names)} names")
    if rot:
        print(f"rotation error median {np.median(rot):.3f} deg, max {max(rot):.3f} deg")
        print(f"position error median {np.median(pos):.3f} %, max {max(pos):.3f} % "
              f"of extent {extent:.3f} ({args.extent})")


if __name__ == "__main__":
    main()
