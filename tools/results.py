"""The project's headline results: one record per measurement under docs/results/data/, the README rendered from them.

Each headline number is written once, into a JSON record ``docs/results/data/NAME.json``, by the command that
measured it; the README's result table and its run times are rendered from those records, never typed by hand.

    python tools/results.py measure NAME [NAME ...]   # run a measurement's command, write its record
    python tools/results.py import NAME FILE          # make a record from what a command wrote (table --out, ...)
    python tools/results.py render                    # rewrite the README's rendered blocks from the records
    python tools/results.py check                     # exit 1 when the README disagrees with the records
    python tools/results.py list                      # each record: its command, commit, date

A record holds::

    {"name": ..., "command": the exact command that measured it, "data": what it ran on,
     "commit": the commit measured, "date": YYYY-MM-DD, "machine": the CPU, "values": {key: number or text},
     "page": the docs page that gives the full table}

``measure`` knows how to run and read each measurement that fits a session on a 2-core CPU (:data:`MEASUREMENTS`).
The long ones (Table 6 over three seeds: hours) are read from the command's own output with ``import``; records whose
measurement is too long to repeat say which command wrote the numbers and at which commit (``"commit"``).
"""
from __future__ import annotations

import argparse
import datetime as _dt
import json
import os
import platform
import re
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
DATA_DIR = ROOT / "docs" / "results" / "data"
README = ROOT / "README.md"
BEGIN = "<!-- rendered by tools/results.py from docs/results/data: {block} -->"
END = "<!-- end of {block} -->"


# --- records ------------------------------------------------------------------------------------------------------

def record_path(name: str, data_dir: Path = DATA_DIR) -> Path:
    """Return the path of record ``name``."""
    if not re.fullmatch(r"[a-z0-9_]+", name):
        raise ValueError(f"a record name is lower-case letters, digits and underscores; got {name!r}")
    return data_dir / f"{name}.json"


def load_record(name: str, data_dir: Path = DATA_DIR) -> dict[str, Any]:
    """Return record ``name``, or raise FileNotFoundError naming the command that writes it."""
    path = record_path(name, data_dir)
    if not path.is_file():
        raise FileNotFoundError(f"{path.relative_to(ROOT) if path.is_relative_to(ROOT) else path}: no such record; "
                                f"write it with `python tools/results.py measure {name}` or `import`")
    record = json.loads(path.read_text(encoding="utf-8"))
    for key in ("name", "command", "data", "commit", "date", "values", "page"):
        if key not in record:
            raise ValueError(f"{path}: record lacks {key!r}")
    return record


def write_record(record: dict[str, Any], data_dir: Path = DATA_DIR) -> Path:
    """Write ``record`` (sorted keys, two-space indent, newline at the end); return its path."""
    path = record_path(record["name"], data_dir)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".json.tmp")
    tmp.write_text(json.dumps(record, indent=2, sort_keys=True, allow_nan=False) + "\n", encoding="utf-8")
    tmp.replace(path)
    return path


def _git_commit() -> str:
    out = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True)
    dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], cwd=ROOT, capture_output=True,
                           text=True).stdout.strip()
    return out.stdout.strip() + ("+changes" if dirty else "") if out.returncode == 0 else "unknown"


def _machine() -> str:
    model = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return f"{os.cpu_count()} cores, {model}"


def new_record(name: str, command: str, data: str, values: dict[str, Any], page: str) -> dict[str, Any]:
    """Return a record of a measurement made now, on this machine, at this commit."""
    return {"name": name, "command": command, "data": data, "values": values, "page": page,
            "commit": _git_commit(), "date": _dt.date.today().isoformat(), "machine": _machine()}


# --- measurements -------------------------------------------------------------------------------------------------

def _run_command(argv: list[str]) -> tuple[float, float]:
    """Run ``python -m evio_lib ARGV``; return (wall, CPU of the child) seconds; raise on failure."""
    before = os.times()
    start = time.perf_counter()
    done = subprocess.run([sys.executable, "-m", "evio_lib", *argv], cwd=ROOT, capture_output=True, text=True)
    wall = time.perf_counter() - start
    after = os.times()
    if done.returncode != 0:
        raise RuntimeError(f"`python -m evio_lib {' '.join(argv)}` failed ({done.returncode}): "
                           f"{done.stderr.strip().splitlines()[-1:] or done.stdout[-300:]}")
    cpu = (after.children_user - before.children_user) + (after.children_system - before.children_system)
    return wall, cpu


def _run_metrics(argv: list[str]) -> dict[str, Any]:
    """Run ``run ... --out TMP`` and return its metrics.json."""
    with tempfile.TemporaryDirectory(prefix="evio-results-") as tmp:
        out = Path(tmp) / "run"
        _run_command([*argv, "--out", str(out)])
        return json.loads((out / "metrics.json").read_text(encoding="utf-8"))


def measure_run_default() -> dict[str, Any]:
    record = _run_metrics(["run"])
    m = record["metrics"]
    values = {"percent_of_distance": round(m["percent_of_distance"], 2), "distance_m": round(m["distance_m"], 1),
              "rmse_m": round(m["rmse_m"], 3), "ate_se3_m": round(m["ate_se3_m"], 3),
              "track_length_mean": round(record["track_length_mean"], 1)}
    return new_record("run_default", "python -m evio_lib run --out OUT",
                      "the simulated boxes_like room, 60 s, seed 0: SIFT on the APS frames", values,
                      "docs/results/pipeline.md")


def _euroc_path() -> Path:
    path = ROOT.parent / "shared" / "data" / "real" / "euroc_V1_01_easy_micro"
    if not path.is_dir():
        raise FileNotFoundError(f"{path}: the EuRoC V1_01 slice is not beside this checkout")
    return path


def measure_run_euroc() -> dict[str, Any]:
    record = _run_metrics(["run", str(_euroc_path())])
    m = record["metrics"]
    values = {"rmse_m": round(m["rmse_m"], 3), "ate_se3_m": round(m["ate_se3_m"], 3),
              "zupt_frames": int(m["zupt_frames"]), "frames": int(m["frames"])}
    return new_record("run_euroc", "python -m evio_lib run ../shared/data/real/euroc_V1_01_easy_micro --out OUT",
                      "the real EuRoC V1_01 slice (4.7 s, the MAV standing on the ground)", values,
                      "docs/results/pipeline.md")


#: name -> a function that runs the measurement and returns its record.
MEASUREMENTS: dict[str, Callable[[], dict[str, Any]]] = {
    "run_default": measure_run_default,
    "run_euroc": measure_run_euroc,
}


def import_table(name: str, file: Path) -> dict[str, Any]:
    """Return a record of Table 6 rows from the ``table.json`` that ``table --out OUT`` wrote."""
    rows = json.loads(Path(file).read_text(encoding="utf-8"))
    values: dict[str, Any] = {}
    for row in rows:
        key = f"{row['preset']}.{row['key']}"
        values[f"{key}.mean"] = round(row["percent_mean"], 2)
        values[f"{key}.std"] = round(row["percent_std"], 2)
    return new_record(name, f"python -m evio_lib table --out OUT (imported from {Path(file).name})",
                      "Table 6 rows, mean and standard deviation of % of distance over the seeds", values,
                      "docs/results/pipeline.md")


# --- rendering ----------------------------------------------------------------------------------------------------

def _fmt(value: Any, spec: str = "") -> str:
    return format(value, spec) if spec else str(value)


class Values:
    """The values of every record, looked up as ``name.key`` in the templates below."""

    def __init__(self, data_dir: Path = DATA_DIR):
        self.data_dir = data_dir
        self.records: dict[str, dict[str, Any]] = {}
        self.used: set[str] = set()

    def record(self, name: str) -> dict[str, Any]:
        if name not in self.records:
            self.records[name] = load_record(name, self.data_dir)
        self.used.add(name)
        return self.records[name]

    def __call__(self, name: str, key: str) -> Any:
        values = self.record(name)["values"]
        if key not in values:
            raise KeyError(f"record {name} has no value {key!r} (it has {sorted(values)})")
        return values[key]


#: The README's headline table: (what, result template, record whose page is linked). A template names values as
#: {record.key[:format]}; every number of the README comes from such a template.
HEADLINE: tuple[tuple[str, str, str], ...] = (
    ("The default `run`: SIFT on the APS frames of the simulated room, 60 s",
     "**{run_default.percent_of_distance} %** of {run_default.distance_m} m travelled, RMSE {run_default.rmse_m} m",
     "run_default"),
    ("Table 6, simulated room, APS frames, seeds 0-2 (% of distance, mean ± std)",
     "SIFT {table6.boxes_like.sift_aps.mean:.2f} ± {table6.boxes_like.sift_aps.std:.2f}, "
     "KLT {table6.boxes_like.klt_aps.mean:.2f} ± {table6.boxes_like.klt_aps.std:.2f}, "
     "CNN {table6.boxes_like.cnn_aps.mean:.2f} ± {table6.boxes_like.cnn_aps.std:.2f}",
     "table6"),
    ("Table 6, simulated terrain, APS frames, seeds 0-2 (% of distance, mean ± std)",
     "SIFT {table6.aerial_like.sift_aps.mean:.2f} ± {table6.aerial_like.sift_aps.std:.2f}, "
     "KLT {table6.aerial_like.klt_aps.mean:.2f} ± {table6.aerial_like.klt_aps.std:.2f}, "
     "CNN {table6.aerial_like.cnn_aps.mean:.2f} ± {table6.aerial_like.cnn_aps.std:.2f}",
     "table6"),
    ("Events against frames in fast motion (the room's last 4 s at twice its speed, 20 ms exposure; KLT, seeds 0-2)",
     "motion-compensated event frames **{events_fast.mc_events_percent} %**, APS frames "
     "{events_fast.aps_percent} % of distance",
     "events_fast"),
    ("A real still start: `run` on the EuRoC V1_01 slice (4.7 s)",
     "ATE {run_euroc.ate_se3_m} m, RMSE {run_euroc.rmse_m} m",
     "run_euroc"),
    ("Feature network against SIFT, homography correctness at 3 px (held-out viewpoint / illumination pairs)",
     "CNN (`photos_detdesc`, fine-tuned on photographs) on its image pyramid "
     "**{features_photos_detdesc.viewpoint_cnn:.3f}** / {features_photos_detdesc.illumination_cnn:.3f}; the network "
     "before that fine-tuning {features_pyramid.viewpoint_cnn:.3f} / {features_pyramid.illumination_cnn:.3f}, at one "
     "level {features.viewpoint_cnn:.3f} / {features.illumination_cnn:.3f}; SIFT {features.viewpoint_sift:.3f} / "
     "{features.illumination_sift:.3f}",
     "features_photos_detdesc"),
    ("Events to frames, SSIM on held-out simulated stretches (room gentle / room fast / terrain)",
     "network {reconstruction.ssim_network_gentle:.3f} / {reconstruction.ssim_network_fast:.3f} / "
     "{reconstruction.ssim_network_aerial:.3f}; high-pass filter {reconstruction.ssim_highpass_gentle:.3f} / "
     "{reconstruction.ssim_highpass_fast:.3f} / {reconstruction.ssim_highpass_aerial:.3f}",
     "reconstruction"),
    ("Events to frames, speed at 240 x 180 on 2 threads (int8 network)",
     "{reconstruction_speed.int8_fps_2threads} frames/s",
     "reconstruction_speed"),
    ("The MSCKF on perfect tracks (room 60 s / terrain 40 s)",
     "{msckf.boxes_percent_range} % / {msckf.aerial_percent_range} % of distance; pose NEES "
     "{msckf.nees_pose} (95 % band {msckf.nees_band})",
     "msckf"),
)

#: The run times quoted beside the README's commands.
TIMES_TEMPLATE = ("From a clean clone on a 2-core CPU the tests take {times.tests_s} s ({times.tests_cpu_s} s of CPU, "
                  "the install included) and the course {times.course_s} s ({times.course_cpu_s} s of CPU); each "
                  "lesson's time and the pipeline's speed are on the [speed page](docs/results/speed.md).")

_FIELD = re.compile(r"\{([a-z0-9_]+)\.([^}:]+)(?::([^}]*))?\}")


def fill(template: str, values: Values) -> str:
    """Return ``template`` with each {record.key[:spec]} replaced by the record's value."""
    return _FIELD.sub(lambda m: _fmt(values(m.group(1), m.group(2)), m.group(3) or ""), template)


def render_blocks(data_dir: Path = DATA_DIR) -> dict[str, str]:
    """Return the README's rendered blocks: 'headline' (the table) and 'times' (one sentence)."""
    values = Values(data_dir)
    lines = ["| result | measured | details |", "|---|---|---|"]
    for what, template, name in HEADLINE:
        record = values.record(name)
        page = record["page"]
        lines.append(f"| {what} | {fill(template, values)} | [{Path(page.split('#')[0]).stem}]({page}) |")
    return {"headline": "\n".join(lines), "times": fill(TIMES_TEMPLATE, values)}


def apply_blocks(text: str, blocks: dict[str, str]) -> str:
    """Return ``text`` with each rendered block replaced; raise ValueError when a block's markers are missing."""
    for block, body in blocks.items():
        begin, end = BEGIN.format(block=block), END.format(block=block)
        pattern = re.compile(re.escape(begin) + r"\n.*?\n?" + re.escape(end), re.S)
        if not pattern.search(text):
            raise ValueError(f"README.md lacks the markers of block {block!r}: {begin} ... {end}")
        text = pattern.sub(lambda _: f"{begin}\n{body}\n{end}", text, count=1)
    return text


def check_readme(readme: Path = README, data_dir: Path = DATA_DIR) -> list[str]:
    """Return the README's disagreements with the records (empty when it is up to date)."""
    text = readme.read_text(encoding="utf-8")
    expected = apply_blocks(text, render_blocks(data_dir))
    if expected == text:
        return []
    return ["README.md's rendered blocks differ from the records: run `python tools/results.py render`"]


# --- command line -------------------------------------------------------------------------------------------------

def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python tools/results.py", description=__doc__.split("\n\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)
    p = sub.add_parser("measure", help="run measurements and write their records")
    p.add_argument("names", nargs="+", choices=sorted(MEASUREMENTS))
    p = sub.add_parser("import", help="make a record from a command's output file (table.json of `table --out`)")
    p.add_argument("name")
    p.add_argument("file", type=Path)
    sub.add_parser("render", help="rewrite the README's rendered blocks")
    sub.add_parser("check", help="exit 1 when the README disagrees with the records")
    sub.add_parser("list", help="list the records")
    args = parser.parse_args(argv)
    try:
        if args.command == "measure":
            for name in args.names:
                print(f"wrote {write_record(MEASUREMENTS[name]()).relative_to(ROOT)}")
        elif args.command == "import":
            if not args.file.is_file():
                raise FileNotFoundError(f"{args.file}: no such file (expected the table.json of `table --out`)")
            print(f"wrote {write_record(import_table(args.name, args.file)).relative_to(ROOT)}")
        elif args.command == "render":
            README.write_text(apply_blocks(README.read_text(encoding="utf-8"), render_blocks()), encoding="utf-8")
            print("README.md rendered")
        elif args.command == "check":
            problems = check_readme()
            for problem in problems:
                print(problem, file=sys.stderr)
            return 1 if problems else 0
        else:
            for path in sorted(DATA_DIR.glob("*.json")):
                r = load_record(path.stem)
                print(f"{r['name']:22s} {r['date']} {r['commit']:>16s}  {r['command']}")
    except (OSError, ValueError, KeyError, RuntimeError) as error:
        print(f"error: {error}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
