#!/usr/bin/env python3
"""COLMAP 4 through pycolmap, driven with COLMAP's own command-line names and options.

damage-twin's structure-from-motion pipeline (src/scene/sfm) runs COLMAP one command at a time
(`colmap feature_extractor --database_path … --SiftExtraction.max_num_features 8192`, …) and
reads COLMAP's log lines for progress. This script takes exactly those commands and options and
runs them with pycolmap (the PyPI wheel of COLMAP 4, CPU only), so the pipeline needs no other
code path: `damage-twin pose --engine pycolmap` writes this file into the dataset's colmap/
folder and runs `python3 pycolmap_engine.py COMMAND --Option value …`. COLMAP's own log lines
(glog, on stderr) are what the progress parser reads; the lines this script prints are plain.

Only the commands and options the pipeline uses are understood; any other is refused with exit
status 2 and a line naming it, never ignored. Exit status 1: COLMAP failed (the message says
how); a mapper that makes no model prints "No good initial image pair found" as COLMAP does.

docs/POSE.md has the measurements that compare this engine with Debian's COLMAP 3.8 CLI.
"""

import os
import sys

USAGE_ERROR = 2
FAILED = 1


def fail(message, status=FAILED):
    print(f"pycolmap_engine: {message}", file=sys.stderr, flush=True)
    sys.exit(status)


def parse_options(args):
    """`--Name value` pairs as a dict; every option takes one value, as the pipeline passes."""
    options = {}
    i = 0
    while i < len(args):
        name = args[i]
        if not name.startswith("--") or i + 1 >= len(args):
            fail(f"expected --Option value pairs, got {name!r}", USAGE_ERROR)
        options[name[2:]] = args[i + 1]
        i += 2
    return options


class Options:
    """The command's options, each taken once; `finish` refuses any left untaken."""

    def __init__(self, command, values):
        self.command = command
        self.values = dict(values)

    def take(self, name, convert=str, default=None, required=False):
        if name not in self.values:
            if required:
                fail(f"{self.command} needs --{name}", USAGE_ERROR)
            return default
        text = self.values.pop(name)
        try:
            return convert(text)
        except ValueError:
            fail(f"{self.command}: --{name} {text!r} is not a {convert.__name__}", USAGE_ERROR)

    def finish(self):
        if self.values:
            names = ", ".join(f"--{n}" for n in sorted(self.values))
            fail(
                f"{self.command}: option(s) {names} not supported by the pycolmap engine "
                f"(use --engine colmap, Debian's COLMAP CLI)",
                USAGE_ERROR,
            )


def flag(text):
    if text not in ("0", "1", "true", "false"):
        raise ValueError(text)
    return text in ("1", "true")


def read_list(path):
    with open(path, encoding="utf-8") as f:
        return [line.strip() for line in f if line.strip()]


def device(pycolmap, opts, prefix):
    if opts.take(f"{prefix}.use_gpu", flag, False):
        fail(f"--{prefix}.use_gpu 1: this engine runs on the CPU", USAGE_ERROR)
    return pycolmap.Device.cpu


def matching_options(pycolmap, opts):
    matching = pycolmap.FeatureMatchingOptions()
    threads = opts.take("SiftMatching.num_threads", int)
    if threads is not None:
        matching.num_threads = threads
    return matching, device(pycolmap, opts, "SiftMatching")


def feature_extractor(pycolmap, opts):
    db = opts.take("database_path", required=True)
    images = opts.take("image_path", required=True)
    names = opts.take("image_list_path", read_list, [])
    reader = pycolmap.ImageReaderOptions()
    single = opts.take("ImageReader.single_camera", flag, False)
    # Set only when given: pycolmap shows an unset path as ".", and "." set is a mask folder.
    for name, field in [
        ("ImageReader.camera_model", "camera_model"),
        ("ImageReader.camera_params", "camera_params"),
        ("ImageReader.mask_path", "mask_path"),
    ]:
        value = opts.take(name)
        if value is not None:
            setattr(reader, field, value)
    extraction = pycolmap.FeatureExtractionOptions()
    threads = opts.take("SiftExtraction.num_threads", int)
    if threads is not None:
        extraction.num_threads = threads
    extraction.sift.max_num_features = opts.take(
        "SiftExtraction.max_num_features", int, extraction.sift.max_num_features
    )
    dev = device(pycolmap, opts, "SiftExtraction")
    opts.finish()
    mode = pycolmap.CameraMode.SINGLE if single else pycolmap.CameraMode.AUTO
    pycolmap.extract_features(
        db,
        images,
        image_names=names,
        camera_mode=mode,
        reader_options=reader,
        extraction_options=extraction,
        device=dev,
    )
    # COLMAP logs a photo it cannot read (or whose mask it cannot read) and goes on; a database
    # left without a single photo's features is a failure here, not a mystery in the mapper.
    database = pycolmap.Database.open(db)
    read = sum(1 for image in database.read_all_images() if database.num_keypoints_for_image(image.image_id) > 0)
    database.close()
    if read == 0:
        fail("no photo's features were extracted (see the lines above)")


def exhaustive_matcher(pycolmap, opts):
    db = opts.take("database_path", required=True)
    matching, dev = matching_options(pycolmap, opts)
    opts.finish()
    pycolmap.match_exhaustive(db, matching_options=matching, device=dev)


def sequential_matcher(pycolmap, opts):
    db = opts.take("database_path", required=True)
    matching, dev = matching_options(pycolmap, opts)
    overlap = opts.take("SequentialMatching.overlap", int, 10)
    quadratic = opts.take("SequentialMatching.quadratic_overlap", flag, True)
    opts.finish()
    # COLMAP 3.8's quadratic overlap adds the photos 2^k ahead to the `overlap` next ones;
    # COLMAP 4's pairs a photo with the ones 2^k ahead only (on lund: 114 pairs instead of 3.8's
    # ~250, and 3 of 29 photos registered). The pipeline means 3.8's: the next ones first, then
    # the quadratic ones (a pair already matched is not matched again).
    for quadratic_pass in [False, True] if quadratic else [False]:
        pairing = pycolmap.SequentialPairingOptions()
        pairing.overlap = overlap
        pairing.quadratic_overlap = quadratic_pass
        pycolmap.match_sequential(
            db, matching_options=matching, pairing_options=pairing, device=dev
        )


def spatial_matcher(pycolmap, opts):
    db = opts.take("database_path", required=True)
    matching, dev = matching_options(pycolmap, opts)
    # COLMAP 4 keeps the photos' GPS as position priors and pairs by them: the 3.8 flag
    # `is_gps 1` is what it always does, `0` (positions already metric) it cannot be told.
    if not opts.take("SpatialMatching.is_gps", flag, True):
        fail("--SpatialMatching.is_gps 0 is not supported by COLMAP 4's spatial matcher", USAGE_ERROR)
    opts.finish()
    pycolmap.match_spatial(db, matching_options=matching, device=dev)


def matches_importer(pycolmap, opts):
    db = opts.take("database_path", required=True)
    pairs = opts.take("match_list_path", required=True)
    kind = opts.take("match_type", str, "pairs")
    if kind != "pairs":
        fail(f"--match_type {kind}: only a pair list (pairs) is supported", USAGE_ERROR)
    matching, dev = matching_options(pycolmap, opts)
    opts.finish()
    pairing = pycolmap.ImportedPairingOptions()
    pairing.match_list_path = pairs
    pycolmap.match_image_pairs(db, matching_options=matching, pairing_options=pairing, device=dev)


# `--Mapper.X` options: where pycolmap keeps them (the pipeline's options or its mapper's) and
# their type. COLMAP 4 renamed fix_existing_images to fix_existing_frames (a frame is an image
# on a one-camera rig, as every photo here is).
PIPELINE_OPTIONS = {
    "num_threads": ("num_threads", int),
    "multiple_models": ("multiple_models", flag),
    "ba_refine_principal_point": ("ba_refine_principal_point", flag),
    "ba_refine_focal_length": ("ba_refine_focal_length", flag),
    "ba_refine_extra_params": ("ba_refine_extra_params", flag),
    "fix_existing_images": ("fix_existing_frames", flag),
    "min_num_matches": ("min_num_matches", int),
    "random_seed": ("random_seed", int),
}
MAPPER_OPTIONS = {
    "init_min_num_inliers": int,
    "init_max_error": float,
    "init_min_tri_angle": float,
    "abs_pose_min_num_inliers": int,
    "abs_pose_min_inlier_ratio": float,
    "abs_pose_max_error": float,
}


def mapper(pycolmap, opts):
    db = opts.take("database_path", required=True)
    images = opts.take("image_path", required=True)
    output = opts.take("output_path", required=True)
    input_path = opts.take("input_path", str, "")
    options = pycolmap.IncrementalPipelineOptions()
    names = opts.take("image_list_path", read_list)
    if names is not None:
        options.image_names = names
    for name, (field, convert) in PIPELINE_OPTIONS.items():
        value = opts.take(f"Mapper.{name}", convert)
        if value is not None:
            setattr(options, field, value)
    for name, convert in MAPPER_OPTIONS.items():
        value = opts.take(f"Mapper.{name}", convert)
        if value is not None:
            setattr(options.mapper, name, value)
    # The incremental mapper keeps its own copy of the flag as well.
    options.mapper.fix_existing_frames = options.fix_existing_frames
    opts.finish()
    os.makedirs(output, exist_ok=True)
    models = pycolmap.incremental_mapping(
        db, images, output, options=options, input_path=input_path
    )
    if not models:
        fail("No good initial image pair found (or no photos with matches): no model was made")
    for index, model in sorted(models.items()):
        print(
            f"model {index}: {model.num_reg_images()} registered images, "
            f"{model.num_points3D()} points",
            flush=True,
        )


COMMANDS = {
    "feature_extractor": feature_extractor,
    "exhaustive_matcher": exhaustive_matcher,
    "sequential_matcher": sequential_matcher,
    "spatial_matcher": spatial_matcher,
    "matches_importer": matches_importer,
    "mapper": mapper,
}


def main(argv):
    if len(argv) < 2:
        fail(f"usage: {argv[0]} COMMAND [--Option value …] (commands: help, "
             + ", ".join(COMMANDS) + ")", USAGE_ERROR)
    command = argv[1]
    if command != "help" and command not in COMMANDS:
        fail(f"unknown command {command!r} (commands: help, {', '.join(COMMANDS)})", USAGE_ERROR)
    opts = Options(command, parse_options(argv[2:]))
    try:
        import pycolmap
    except ImportError as e:
        fail(f"cannot import pycolmap ({e}): install it with `pip install pycolmap`")
    if command == "help":
        print(
            f"{pycolmap.COLMAP_version} (pycolmap {pycolmap.__version__}, "
            f"{pycolmap.COLMAP_build}) -- Structure-from-Motion through damage-twin's "
            f"pycolmap_engine.py",
            flush=True,
        )
        return
    try:
        COMMANDS[command](pycolmap, opts)
    except (RuntimeError, ValueError, OSError) as e:
        fail(f"{command} failed: {e}")


if __name__ == "__main__":
    main(sys.argv)
