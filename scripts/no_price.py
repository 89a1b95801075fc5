"""The price of a "no" and of a match as a user pays it: whole processes, this tree against
another and against the SIFT script, alternately pair by pair.

Usage: python scripts/no_price.py --old OLD_SOURCE_TREE [--nulls FOLDER] [--every 8]
       [--zoom 12] [--big 4] [--rounds 1]

Each run is one process, timed with its peak memory (``/usr/bin/time`` when it exists):
``scalematch LOW HIGH -q`` of this tree (also with ``--no-views``, with the passes of
the preset ``tilt-4``, and with ``--model fundamental``) and of ``--old`` (its
``scalematch.cli.main`` with the tree first on ``sys.path``; also with ``--model
fundamental``), and ``python scripts/sift_reference.py LOW HIGH`` (OpenCV SIFT,
ratio test, RANSAC: what a user would write instead), in turn for each pair, the order of the
ways turned each pair, so that all see the same machine load. The pairs:

* every ``--every``-th null pair stored by ``scalematch lab nulls`` in ``--nulls`` (both
  orders): the time of a "no", its median and its slowest, against SIFT's;
* ``--zoom`` zoom pairs (EVALUATION.md, ratios 2 to 16, seed 0), written as PNG files: the time
  of a match;
* ``--sized`` unrelated pairs of photos of two different scenes, shrunk to two sizes: a 640x480
  high image against a 1 MP low one, and 1 MP against 1 MP (the photo's aspect kept, its
  longer side 640 or 1,280 px), written as PNG files: a "no" at the sizes users mostly match;
* the first ``--big`` unrelated pairs of 12-16 MP photos (``BIG_PAIRS``, the JPEG files
  themselves): a "no" on camera-size photos, seconds and peak MB.

Prints one Markdown table per set, with the command of this run.
"""

from __future__ import annotations

import argparse
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "scripts"))

#: unrelated photos of 16 and 12 MP (4608x3456 and 4032x3024 px); the first is the pair the
#: design notes quote
BIG_PAIRS = (("snowpeak_IMG_2168.JPG", "monstree_IMG_1042.JPG"),
             ("snowpeak_IMG_2280.JPG", "jpegtest_012mp-bus.jpg"),
             ("monstree_IMG_1029.JPG", "snowpeak_IMG_2186.JPG"),
             ("snowpeak_IMG_2282.JPG", "monstree_IMG_1046.JPG"))

#: The command line of a source tree's ``scalematch`` run from another interpreter
TREE_MAIN = "import sys; sys.path.insert(0, {tree!r}); from scalematch.cli import main; main()"


def commands(old: str) -> dict:
    """Each way of matching a pair: (the command before the two paths, the options after)."""
    python = sys.executable
    new = [python, "-c", TREE_MAIN.format(tree=str(ROOT))]
    return {"new": (new, ["-q"]),
            "new --no-views": (new, ["-q", "--no-views"]),
            "new tilt-4": (new, ["-q", "--set", "views.passes=2;4"]),
            "new fundamental": (new, ["-q", "--model", "fundamental"]),
            "old": ([python, "-c", TREE_MAIN.format(tree=old)], ["-q"]),
            "old fundamental": ([python, "-c", TREE_MAIN.format(tree=old)],
                                ["-q", "--model", "fundamental"]),
            "sift": ([python, str(ROOT / "scripts" / "sift_reference.py")], [])}


def compiled(tree: str) -> None:
    """The bytecode of ``tree``'s package written, as installing a wheel writes it: with
    ``PYTHONDONTWRITEBYTECODE`` set (our machines), a source tree's modules are otherwise
    compiled again by every process, about 80 ms of each (docs/design/SPEED.md, "Start-up")."""
    subprocess.run([sys.executable, "-m", "compileall", "-q", str(Path(tree) / "scalematch")],
                   stdout=subprocess.DEVNULL, check=True, env=dict(os.environ,
                                                              PYTHONDONTWRITEBYTECODE=""))


def timed(way: tuple, low: str, high: str) -> tuple:
    """(seconds, peak MB, exit code) of one whole process."""
    cmd, extra = way
    time_bin = shutil.which("time") or ("/usr/bin/time" if Path("/usr/bin/time").exists() else None)
    with tempfile.NamedTemporaryFile("r", suffix=".txt") as out:
        wrap = [time_bin, "-f", "%e %M", "-o", out.name] if time_bin else []
        done = subprocess.run(wrap + cmd + [low, high] + extra, stdout=subprocess.DEVNULL,
                              stderr=subprocess.DEVNULL)
        # the last line: /usr/bin/time writes "Command exited with non-zero status 1" before it
        last = out.read().splitlines()[-1] if time_bin else "nan nan"
        seconds, kb = (float(v) for v in last.split()[:2])
    return seconds, kb / 1024.0, done.returncode


def run_set(name: str, pairs: list, cmds: dict, rounds: int) -> dict:
    """Every pair of ``pairs`` ((low path, high path)) through every command, in turn."""
    got = {k: [] for k in cmds}
    names = list(cmds)
    for r in range(rounds):
        for i, (low, high) in enumerate(pairs):
            turn = names[(i + r) % len(names):] + names[:(i + r) % len(names)]
            for k in turn:
                got[k].append(timed(cmds[k], low, high))
    return got


def table(title: str, got: dict, claims_are_wrong: bool) -> str:
    lines = [f"\n{title}\n", "| | median s | slowest s | peak MB (median) | exit 0 (a match) "
             "| median / SIFT's | median of each pair's s / the first way's |",
             "|---|---:|---:|---:|---:|---:|---:|"]
    sift = statistics.median(s for s, _, _ in got["sift"]) if got.get("sift") else float("nan")
    for k, runs in got.items():
        secs = [s for s, _, _ in runs]
        med = statistics.median(secs)
        matched = sum(1 for _, _, c in runs if c == 0)
        lines.append(f"| {k} | {med:.2f} | {max(secs):.2f} | "
                     f"{statistics.median(m for _, m, _ in runs):.0f} | {matched} of {len(runs)}"
                     f"{' (false)' if claims_are_wrong and matched and k != 'sift' else ''} | "
                     f"{med / sift:.2f} | {per_pair(runs, next(iter(got.values()))):.2f} |")
    return "\n".join(lines)


def per_pair(runs: list, base: list) -> float:
    """The median over pairs of the ratio of each pair's seconds to ``base``'s."""
    return statistics.median(a[0] / b[0] for a, b in zip(runs, base) if b[0] > 0)


def stored_nulls(folder: Path, every: int) -> list:
    from scalematch.lab.nulls import TRUE_KIND, read_manifest

    stored = read_manifest(folder)
    entries = [e for _, e in sorted(stored.items()) if e["kind"] != TRUE_KIND][::max(every, 1)]
    pairs = [(str(folder / e["low_file"]), str(folder / e["high_file"])) for e in entries]
    return pairs + [(h, lo) for lo, h in pairs]


def zoom_files(n: int, folder: Path) -> list:
    import cv2
    from scalematch.lab.datasets import find_shared, list_photos
    from scalematch.lab.synthetic import pairs_from_photos

    photos = list_photos(find_shared())
    step = max(len(photos) // max(n, 1), 1)
    ratios = (2.0, 3.0, 4.0, 6.0, 8.0, 10.0, 12.0, 16.0)
    out = []
    for k, photo in enumerate(photos[::step][:n]):  # one ratio a photo, in turn
        pair = next(pairs_from_photos([photo], [ratios[k % len(ratios)]], 0))
        low, high = folder / f"zoom{k}_low.png", folder / f"zoom{k}_high.png"
        cv2.imwrite(str(low), pair.low.clip(0, 255).astype("uint8"))
        cv2.imwrite(str(high), pair.high.clip(0, 255).astype("uint8"))
        out.append((str(low), str(high)))
    return out


def sized_files(n: int, folder: Path) -> dict:
    """``n`` unrelated pairs at each size: {title: [(low path, high path)]}. Photo k is paired
    with the first photo after it of another scene (``datasets.other_scene``)."""
    import cv2
    from scalematch.lab.datasets import find_shared, list_photos, other_scene

    photos = list_photos(find_shared())
    names = [p.name for p in photos]
    step = max(len(photos) // max(n, 1), 1)
    sizes = {"640x480 high against a 1 MP low image": (1280, 640),
             "1 MP against 1 MP": (1280, 1280)}
    out = {title: [] for title in sizes}
    for k in range(0, step * n, step):
        low_img = cv2.imread(str(photos[k]), cv2.IMREAD_GRAYSCALE)
        high_img = cv2.imread(str(photos[other_scene(names, k, [names[k]])]),
                              cv2.IMREAD_GRAYSCALE)
        for title, (low_side, high_side) in sizes.items():
            paths = []
            for name, img, side in (("low", low_img, low_side), ("high", high_img, high_side)):
                f = side / max(img.shape)
                small = cv2.resize(img, (round(img.shape[1] * f), round(img.shape[0] * f)),
                                   interpolation=cv2.INTER_AREA)
                path = folder / f"sized{k}_{side}_{high_side}_{name}.png"
                cv2.imwrite(str(path), small)
                paths.append(str(path))
            out[title].append(tuple(paths))
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--old", required=True, help="source tree of the version compared with")
    ap.add_argument("--nulls", default="bench-out/nulls/pairs-seed0",
                    help="folder of null pairs stored by `scalematch lab nulls`")
    ap.add_argument("--every", type=int, default=8, help="every N-th stored null pair")
    ap.add_argument("--zoom", type=int, default=12, help="zoom pairs (one photo each)")
    ap.add_argument("--sized", type=int, default=8,
                    help="unrelated pairs at 640x480 against 1 MP and at 1 MP against 1 MP")
    ap.add_argument("--big", type=int, default=4, help="unrelated 12-16 MP pairs")
    ap.add_argument("--ways", default="new,new --no-views,old,sift",
                    help="the ways timed, comma-separated: " + ", ".join(commands("")))
    ap.add_argument("--rounds", type=int, default=1, help="rounds over each set")
    a = ap.parse_args()
    every_way = commands(a.old)
    cmds = {k: every_way[k] for k in a.ways.split(",")}
    for tree in {str(ROOT)} | ({a.old} if "old" in cmds else set()):
        compiled(tree)
    print(f"`python scripts/no_price.py --old {a.old} --nulls {a.nulls} --every {a.every} "
          f"--sized {a.sized} --zoom {a.zoom} --big {a.big} --rounds {a.rounds} "
          f"--ways \"{a.ways}\"`; load average before "
          f"{os.getloadavg()[0]:.1f}")
    if a.every and Path(a.nulls).is_dir():
        got = run_set("nulls", stored_nulls(Path(a.nulls), a.every), cmds, a.rounds)
        print(table("Null pairs (both orders): the time of a \"no\"", got, True))
    if a.sized:
        with tempfile.TemporaryDirectory() as tmp:
            for title, pairs in sized_files(a.sized, Path(tmp)).items():
                got = run_set("sized", pairs, cmds, a.rounds)
                print(table(f"Unrelated pairs, {title}: the time of a \"no\"", got, True))
    if a.zoom:
        with tempfile.TemporaryDirectory() as tmp:
            got = run_set("zoom", zoom_files(a.zoom, Path(tmp)), cmds, a.rounds)
        print(table("Zoom pairs: the time of a match", got, False))
    if a.big:
        from scalematch.lab.datasets import find_shared

        photos = find_shared() / "data" / "photos"
        pairs = [(str(photos / x), str(photos / y)) for x, y in BIG_PAIRS[:a.big]]
        got = run_set("big", pairs, cmds, a.rounds)
        print(table("Unrelated 12-16 MP photos: a \"no\" on camera-size images", got, True))
    print(f"\nload average after {os.getloadavg()[0]:.1f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
