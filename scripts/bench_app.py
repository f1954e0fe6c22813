"""Browser benchmark of the app: the time from releasing the Distance slider to the new point
cloud drawn on screen, at 64, 128 and 256 pixels per side (paper scene, real headless Chromium).

    .venv/bin/python scripts/bench_app.py [--repeats 20] [--sizes 64 128 256] [--url URL]

It starts the app server itself (unless --url is given), drags the Distance slider back and
forth between 420 m and 600 m and, for each drag, measures in the page from the mouse release to
the moment the frame of the final value has been painted (the page logs each frame after two
animation frames, once vtk.js has rendered it). Also printed: the same from the last mouse move
of the drag (the value's last change, a few ms before the release).
"""

from __future__ import annotations

import argparse
import math
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))  # the drivers: support.*

from playwright.sync_api import sync_playwright  # noqa: E402
from support.launch import (  # noqa: E402
    CHROMIUM_ARGS,
    CHROMIUM_PATH,
    JS_STATE,
    app_server,
    chromium_missing_message,
    set_field,
    wait_first_frame,
    wait_settled,
)

from app.state import SPECS  # noqa: E402

DISTANCES_M = (420.0, 600.0)
LISTENERS = """() => {
  window.lmapdBench = { release: 0, lastMove: 0 };
  document.addEventListener('pointermove', e => {
    if (e.buttons) window.lmapdBench.lastMove = performance.now();
  }, true);
  document.addEventListener('pointerup', () => {
    window.lmapdBench.release = performance.now();
  }, true);
}"""
NEW_FRAME_SETTLED = """(n0) => {
  const s = window.trame.state, frames = window.lmapdFrames || [];
  return frames.length > n0 && !s.get('busy')
      && frames[frames.length - 1].key === s.get('frame_key');
}"""


def slider_x(page, distance_m: float) -> tuple[float, float]:
    """Screen position of ``distance_m`` on the (log-scale) Distance slider's track."""
    box = page.locator(".slider-distance_m .v-slider-track").bounding_box()
    spec = SPECS["distance_m"]
    u = (math.log10(distance_m) - math.log10(spec.lo)) / (math.log10(spec.hi) - math.log10(spec.lo))
    return box["x"] + u * box["width"], box["y"] + box["height"] / 2


def drag_distance(page, to_m: float) -> dict:
    """Drag the thumb to ``to_m`` (press, move half-way, move, release); return the
    release->painted and last-move->painted times of the frame of the new value."""
    before = page.evaluate(JS_STATE, "distance_m")
    thumb = page.locator(".slider-distance_m .v-slider-thumb").first.bounding_box()
    n0 = page.evaluate("() => (window.lmapdFrames || []).length")
    x0, y0 = thumb["x"] + thumb["width"] / 2, thumb["y"] + thumb["height"] / 2
    x1, _ = slider_x(page, to_m)
    page.mouse.move(x0, y0)
    page.mouse.down()
    page.mouse.move((x0 + x1) / 2, y0)
    page.mouse.move(x1, y0)
    page.mouse.up()
    time.sleep(0.05)
    if page.evaluate(JS_STATE, "distance_m") == before:
        raise RuntimeError(f"the drag to {to_m} m did not move the slider (still {before} m)")
    page.wait_for_function(NEW_FRAME_SETTLED, arg=n0, timeout=60_000)
    return page.evaluate(
        """() => {
          const f = window.lmapdFrames, b = window.lmapdBench, s = window.trame.state;
          const g = s.get('frame_generation');
          const ofFinal = f.filter(x => x.key === `p${g}` || x.key === `g${g}`);
          const first = ofFinal[0], preset = ofFinal[ofFinal.length - 1];
          return { release_ms: preset.t - b.release, move_ms: preset.t - b.lastMove,
                   first_ms: first.t - b.release, first_kind: first.kind,
                   points: s.get('n_points'), distance_m: s.get('distance_m') };
        }"""
    )


def next_distance(page) -> float:
    """The benchmark distance farther from the current one."""
    current = page.evaluate(JS_STATE, "distance_m")
    return max(DISTANCES_M, key=lambda d: abs(math.log(d / current)))


def bench_size(page, pixels: int, repeats: int) -> dict:
    set_field(page, "pixels", pixels)
    page.wait_for_function(
        "(n) => window.trame.state.get('array_image').pixels === n", arg=pixels, timeout=60_000
    )
    wait_settled(page)
    for _ in range(2):  # warm-up: caches, JIT, buffers
        drag_distance(page, next_distance(page))
    runs = [drag_distance(page, next_distance(page)) for _ in range(repeats)]
    release = [r["release_ms"] for r in runs]
    first = [r["first_ms"] for r in runs]
    move = [r["move_ms"] for r in runs]
    return {
        "pixels": pixels,
        "first_ms": statistics.median(first),
        "first_range": (min(first), max(first)),
        "previews": sum(r["first_kind"] == "preview" for r in runs),
        "median_ms": statistics.median(release),
        "range": (min(release), max(release)),
        "p90_ms": sorted(release)[max(0, math.ceil(0.9 * len(release)) - 1)],
        "median_from_move_ms": statistics.median(move),
        "points": statistics.median(r["points"] for r in runs),
        "repeats": len(runs),
    }


def run(url: str, sizes: list[int], repeats: int) -> list[dict]:
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM_PATH, args=CHROMIUM_ARGS)
        page = browser.new_page(viewport={"width": 1600, "height": 1000})
        page.goto(url)
        wait_first_frame(page)
        wait_settled(page)
        page.evaluate(LISTENERS)
        rows = [bench_size(page, n, repeats) for n in sizes]
        browser.close()
    return rows


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[64, 128, 256])
    parser.add_argument("--repeats", type=int, default=20)
    parser.add_argument(
        "--url",
        help="the address an app already running printed, token included (default: start one)",
    )
    args = parser.parse_args(argv)
    problem = chromium_missing_message()
    if problem:
        print(problem, file=sys.stderr)
        return 1
    t0 = time.perf_counter()
    if args.url:
        rows = run(args.url, args.sizes, args.repeats)
    else:
        with app_server() as url:
            rows = run(url, args.sizes, args.repeats)
    print("Slider release to the new point cloud on screen (Distance 420 <-> 600 m, paper scene,")
    print(f"headless Chromium + SwiftShader, {args.repeats} drags per size): first picture (the")
    print("preview, or the frame itself when it came first) and the chosen preset's picture")
    print()
    print(
        "| pixels | points | first picture, median [range] (ms) | previews shown "
        "| preset's picture, median [range] (ms) | p90 (ms) | from last move (ms) |"
    )
    print("|---:|---:|---:|---:|---:|---:|---:|")
    for r in rows:
        n = r["pixels"]
        print(
            f"| {n} x {n} | {r['points']:,.0f} "
            f"| {r['first_ms']:.0f} [{r['first_range'][0]:.0f}-{r['first_range'][1]:.0f}] "
            f"| {r['previews']}/{r['repeats']} "
            f"| {r['median_ms']:.0f} [{r['range'][0]:.0f}-{r['range'][1]:.0f}] "
            f"| {r['p90_ms']:.0f} | {r['median_from_move_ms']:.0f} |"
        )
    print(f"\n({time.perf_counter() - t0:.0f} s)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
