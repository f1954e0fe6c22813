"""Browser benchmark of the app: the time from releasing the Distance slider to the new point
cloud drawn on screen, at 64, 128 and 256 pixels per side (paper scene, real headless Chromium).

    .venv/bin/python scripts/bench_app.py [--repeats 20] [--sizes 64 128 256] [--url URL]

It starts the app server itself (unless --url is given), drags the Distance slider back and
forth between 420 m and 600 m and, for each drag, measures in the page from the mouse release to
the first picture of the final value (its preview, when one came first) and to the picture of the
chosen fidelity preset's frame. A picture counts once it is on screen: the page logs a frame two
animation frames after the 3D views' last render (with software WebGL the compositor's commit
reads the canvas back, so the picture shows only then). Also printed: the preset's picture from
the last mouse move of the drag (the value's last change, a few ms before the release).
With --vs-no-preview a second server without previews gets the same drags, in turn with the
first's, so both tables come from the same spells of the machine.
"""

from __future__ import annotations

import argparse
import contextlib
import math
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))  # the drivers: support.*

from playwright.sync_api import sync_playwright
from support.launch import (
    CHROMIUM_ARGS,
    CHROMIUM_PATH,
    JS_STATE,
    app_server,
    chromium_missing_message,
    set_field,
    wait_first_frame,
    wait_settled,
)

from app.state import SPECS

DISTANCES_M = (420.0, 600.0)
# A pause before each drag: the browser's work after a frame (garbage collection, raster tasks,
# the charts' deferred redraws) ends before the next drag starts, on either page of a --vs run.
PAUSE_S = 0.4
LISTENERS = """() => {
  window.lmapdBench = { release: 0, lastMove: 0 };
  document.addEventListener('pointermove', e => {
    if (e.buttons) window.lmapdBench.lastMove = performance.now();
  }, true);
  document.addEventListener('pointerup', () => {
    window.lmapdBench.release = performance.now();
  }, true);
}"""
# Each websocket message's arrival time and size (installed before the page's scripts run).
MESSAGES = """
(() => {
  window.lmapdMessages = [];
  const Socket = window.WebSocket;
  window.WebSocket = function (...args) {
    const ws = new Socket(...args);
    ws.addEventListener('message', (e) => window.lmapdMessages.push(
      { t: performance.now(), n: e.data.byteLength || e.data.size || e.data.length || 0 }));
    return ws;
  };
  window.WebSocket.prototype = Socket.prototype;
  Object.assign(window.WebSocket, Socket);
})();
"""
# The time one render of each 3D view takes until its pixels exist (render, then read one pixel
# back, which waits for the software WebGL to finish), median of 5 [ms].
VIEW_RENDER_MS = """() => {
  const out = {};
  for (const ref of ['scene_view', 'cloud_view']) {
    const view = window.trame.refs[ref].$.provides.view;
    const gl = view.container.querySelector('canvas').getContext('webgl2');
    const pixel = new Uint8Array(4), times = [];
    for (let i = 0; i < 5; i++) {
      const t0 = performance.now();
      view.renderWindow.render();
      gl.readPixels(0, 0, 1, 1, gl.RGBA, gl.UNSIGNED_BYTE, pixel);
      times.push(performance.now() - t0);
    }
    out[ref] = times.sort((a, b) => a - b)[2];
  }
  return out;
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
    time.sleep(PAUSE_S)
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
          const big = (window.lmapdMessages || []).filter(m => m.t > b.release && m.n > 4096);
          const arrived = (frame) => {  // the last large message before the frame was applied
            const before = big.filter(m => m.t <= frame.applied);
            return before.length ? before[before.length - 1] : { t: NaN, n: 0 };
          };
          const row = (frame) => ({ message_ms: arrived(frame).t - b.release,
                                    kb: arrived(frame).n / 1024,
                                    applied_ms: frame.applied - b.release,
                                    shown_ms: frame.t - b.release });
          const stages = s.get('stages') || [];
          const server = stages.find(r => r.stage === 'request to page');
          return { release_ms: preset.t - b.release, move_ms: preset.t - b.lastMove,
                   first_ms: first.t - b.release, first_kind: first.kind,
                   first: row(first), preset: row(preset),
                   server_ms: server ? Number(server.ms) : NaN,
                   points: s.get('n_points'), distance_m: s.get('distance_m') };
        }"""
    )


def next_distance(page) -> float:
    """The benchmark distance farther from the current one."""
    current = page.evaluate(JS_STATE, "distance_m")
    return max(DISTANCES_M, key=lambda d: abs(math.log(d / current)))


def summary(pixels: int, runs: list[dict]) -> dict:
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
        "server_ms": statistics.median(r["server_ms"] for r in runs),
        **{
            f"{which}_{part}": statistics.median(r[which][part] for r in runs)
            for which in ("first", "preset")
            for part in ("message_ms", "kb", "applied_ms", "shown_ms")
        },
    }


def set_pixels(page, pixels: int) -> None:
    set_field(page, "pixels", pixels)
    page.wait_for_function(
        "(n) => window.trame.state.get('array_image').pixels === n", arg=pixels, timeout=60_000
    )
    wait_settled(page)
    for _ in range(2):  # warm-up: caches, JIT, buffers
        drag_distance(page, next_distance(page))


def views(page) -> dict:
    """The render time of each 3D view at this array size [ms] (VIEW_RENDER_MS)."""
    wait_settled(page)
    ms = page.evaluate(VIEW_RENDER_MS)
    return {"scene_render_ms": ms["scene_view"], "cloud_render_ms": ms["cloud_view"]}


def run(urls: dict[str, str], sizes: list[int], repeats: int) -> list[dict]:
    """Each server's page gets the same drags, taken in turn (A, B, A, B, ...) so that both
    see the same spells of this shared machine. Each page has a browser of its own: pages of
    one browser take turns in front, and a page coming to the front repaints everything."""
    rows = []
    with sync_playwright() as p:
        pages = {}
        for label, url in urls.items():
            browser = p.chromium.launch(executable_path=CHROMIUM_PATH, args=CHROMIUM_ARGS)
            page = browser.new_page(viewport={"width": 1600, "height": 1000})
            page.add_init_script(MESSAGES)
            page.goto(url)
            wait_first_frame(page)
            wait_settled(page)
            page.evaluate(LISTENERS)
            pages[label] = page
        for n in sizes:
            for page in pages.values():
                set_pixels(page, n)
            runs: dict[str, list[dict]] = {label: [] for label in pages}
            for _ in range(repeats):
                for label, page in pages.items():
                    runs[label].append(drag_distance(page, next_distance(page)))
            for label, page in pages.items():
                rows.append({"mode": label, **summary(n, runs[label]), **views(page)})
        for page in pages.values():
            page.context.browser.close()
    return rows


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[64, 128, 256])
    parser.add_argument("--repeats", type=int, default=20)
    parser.add_argument(
        "--url",
        help="the address an app already running printed, token included (default: start one)",
    )
    parser.add_argument(
        "--vs-no-preview",
        action="store_true",
        help="also start a server with --no-preview and take its drags in turn with the first's",
    )
    args = parser.parse_args(argv)
    problem = chromium_missing_message()
    if problem:
        print(problem, file=sys.stderr)
        return 1
    t0 = time.perf_counter()
    with contextlib.ExitStack() as stack:
        urls = {"previews": args.url or stack.enter_context(app_server())}
        if args.vs_no_preview:
            urls["no preview"] = stack.enter_context(app_server(app_args=("--no-preview",)))
        rows = run(urls, args.sizes, args.repeats)
    print("Slider release to the new point cloud on screen (Distance 420 <-> 600 m, paper scene,")
    print(f"headless Chromium + SwiftShader, {args.repeats} drags per size): first picture (the")
    print("preview, or the frame itself when it came first) and the chosen preset's picture")
    print()
    print(
        "| server | pixels | points | first picture, median [range] (ms) | previews shown "
        "| preset's picture, median [range] (ms) | p90 (ms) | from last move (ms) |"
    )
    print("|---|---:|---:|---:|---:|---:|---:|---:|")
    for r in rows:
        n = r["pixels"]
        print(
            f"| {r['mode']} | {n} x {n} | {r['points']:,.0f} "
            f"| {r['first_ms']:.0f} [{r['first_range'][0]:.0f}-{r['first_range'][1]:.0f}] "
            f"| {r['previews']}/{r['repeats']} "
            f"| {r['median_ms']:.0f} [{r['range'][0]:.0f}-{r['range'][1]:.0f}] "
            f"| {r['p90_ms']:.0f} | {r['median_from_move_ms']:.0f} |"
        )
    print()
    print("Where the time goes (medians, ms after the release; kB: the frame's websocket message;")
    print("server: request to the frame in its state, the page's stage table; render: one render")
    print("of the view until its pixels exist, alone)")
    print()
    print(
        "| server | pixels | picture | message arrives | kB | applied | on screen "
        "| server: request to state | scene view render | cloud view render |"
    )
    print("|---|---:|---|---:|---:|---:|---:|---:|---:|---:|")
    for r in rows:
        n = r["pixels"]
        for which in ("first", "preset"):
            print(
                f"| {r['mode']} | {n} x {n} | {which} | {r[which + '_message_ms']:.0f} "
                f"| {r[which + '_kb']:.0f} | {r[which + '_applied_ms']:.0f} "
                f"| {r[which + '_shown_ms']:.0f} "
                f"| {r['server_ms']:.0f} | {r['scene_render_ms']:.0f} "
                f"| {r['cloud_render_ms']:.0f} |"
            )
    print(f"\n({time.perf_counter() - t0:.0f} s)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
