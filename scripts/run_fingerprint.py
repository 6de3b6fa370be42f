#!/usr/bin/env python3
"""Prints what a run decided, without what depends on timing, so that two runs can be compared.

  scripts/run_fingerprint.py RUN_DIR [--db DB]

The texture database (OUT/textures.db unless --db names another SQLite file): every texture by
its content key, kind, size and lattice; every instance of the run with its layer, the content
key of the texture it names, its transform, fidelity and reuse flag. report.json: every figure
but those that time, size memory or name paths. A refactoring that keeps behaviour prints the
same text; scripts/check_unchanged.sh compares two runs with it.
"""
import argparse
import json
import pathlib
import sqlite3
import sys

# report.json keys that measure time or memory, or name where the run was: they differ between
# two runs of the same binary.
TIMING_KEYS = {
    "wall_s", "fps", "end_to_end_s", "fps_end_to_end", "peak_rss_mb", "rss_growth_mb_per_1000_frames", "latency_ms_p50",
    "latency_ms_p95", "commit_latency_ms_p50", "commit_latency_ms_p95", "describe_queued_ms_p50",
    "describe_queued_ms_p95", "commit_queued_ms_p50", "commit_queued_ms_p95", "db_commit_ms_p50",
    "db_commit_ms_p95", "match_ms_p50", "bitmap_ms_per_m2", "pose_graph_ms", "loop_keyframe_ms",
    "loop_keyframe_cpu_ms", "loop_information_ms", "loop_place_lookup_ms", "loop_place_index_ms",
    "loop_verification_ms", "loop_follow_ms", "loop_follow_frame_ms_max", "loop_wait_s", "stages", "db", "source", "cpu_s_stream", "cpu_ms_per_frame",
    "cpu_cores_stream", "cpu_s_end_of_stream", "cpu_s_finish", "cpu_s_total",
}


def rounded(value):
    """Floats to 9 significant digits: the same computation prints the same text."""
    if isinstance(value, float):
        return float(f"{value:.9g}")
    if isinstance(value, dict):
        return {k: rounded(v) for k, v in value.items()}
    if isinstance(value, list):
        return [rounded(v) for v in value]
    return value


def database_lines(db_path):
    db = sqlite3.connect(f"file:{db_path}?mode=ro", uri=True)
    lines = []
    keys = {}
    for row in db.execute(
            "SELECT id, content_key, kind, width, height, texel_m, lattice_v1x, lattice_v1y, "
            "lattice_v2x, lattice_v2y, source_patch FROM textures ORDER BY content_key"):
        keys[row[0]] = row[1]
        lines.append("texture " + json.dumps(rounded(list(row[1:]))))
    for row in db.execute(
            "SELECT patch_id, version, layer, texture_id, a, b, tx, ty, psnr_db, reused "
            "FROM instances ORDER BY patch_id, layer"):
        values = list(row)
        values[3] = keys.get(values[3], f"missing texture {values[3]}")
        lines.append("instance " + json.dumps(rounded(values)))
    return lines


def report_lines(report_path):
    report = json.loads(report_path.read_text())
    return [f"report {key} {json.dumps(rounded(report[key]))}"
            for key in sorted(report) if key not in TIMING_KEYS]


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run_dir", type=pathlib.Path)
    parser.add_argument("--db", type=pathlib.Path, help="the run's --db (SQLite) if not OUT/textures.db")
    args = parser.parse_args()
    report = args.run_dir / "report.json"
    db = args.db or args.run_dir / "textures.db"
    for path in (report, db):
        if not path.is_file():
            sys.exit(f"run_fingerprint: {path}: not found")
    print("\n".join(database_lines(db) + report_lines(report)))


if __name__ == "__main__":
    main()
