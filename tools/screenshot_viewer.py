"""Screenshot of the rerun web viewer on the sample session, for the README.

Serves the session with ``pslog view SESSION --serve`` on localhost, opens the web viewer in
headless Chromium (Debian's ``chromium``; ``apt-get install chromium``), waits for it to load
(the viewer needs about 40 s under software rendering), and saves a PNG. Chromium is driven
over ``--remote-debugging-pipe`` (the DevTools protocol on file descriptors 3 and 4), so
nothing beyond the standard library is needed.

Run: ``python tools/screenshot_viewer.py [--session samples/throw.mcap]
[--output docs/images/viewer.png] [--wait 60] [--time 0.85 [--time 1.3 ...]]
[--theme light|dark]`` (default: the README's three images, docs/images/viewer-0.3s.png,
viewer-0.85s.png and viewer-1.3s.png)

``--time T`` picks the moment: the session is served up to T seconds and the viewer opens
there (rerun opens at the latest time). With several ``--time``, one PNG per moment,
``<output stem>-<T>s.png``. ``--theme`` sets the page's ``prefers-color-scheme``, which the
web viewer follows.
"""

from __future__ import annotations

import argparse
import base64
import fcntl
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from urllib.parse import quote

ROOT = Path(__file__).resolve().parent.parent
_CHROMIUM_FLAGS = [
    "--headless", "--no-sandbox", "--disable-gpu", "--use-angle=swiftshader",
    "--enable-unsafe-swiftshader", "--disable-quic", "--no-first-run",
    "--disable-background-networking", "--disable-component-update", "--disable-sync",
    "--hide-scrollbars", "--remote-debugging-pipe",
]


class _DevTools:
    """Minimal DevTools-protocol client over Chromium's pipe (NUL-terminated JSON)."""

    def __init__(self, chromium: str, user_data: str, width: int, height: int) -> None:
        to_chrome_r, self._to_chrome = os.pipe()
        self._from_chrome, from_chrome_w = os.pipe()

        def fds_3_and_4() -> None:  # Chromium reads commands on fd 3, writes replies on fd 4
            high_r = fcntl.fcntl(to_chrome_r, fcntl.F_DUPFD, 10)  # out of the way of 3 and 4
            high_w = fcntl.fcntl(from_chrome_w, fcntl.F_DUPFD, 10)
            os.dup2(high_r, 3)
            os.dup2(high_w, 4)

        self.process = subprocess.Popen(
            [chromium, *_CHROMIUM_FLAGS, f"--user-data-dir={user_data}",
             f"--window-size={width},{height}", "about:blank"],
            pass_fds=(3, 4), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
            preexec_fn=fds_3_and_4)
        os.close(to_chrome_r)
        os.close(from_chrome_w)
        self._buffer = b""
        self._next_id = 0

    def call(self, method: str, params: dict | None = None, session: str | None = None) -> dict:
        self._next_id += 1
        message = {"id": self._next_id, "method": method, "params": params or {}}
        if session:
            message["sessionId"] = session
        os.write(self._to_chrome, json.dumps(message).encode() + b"\0")
        while True:
            while b"\0" not in self._buffer:
                chunk = os.read(self._from_chrome, 1 << 20)
                if not chunk:
                    raise RuntimeError(f"chromium closed the pipe during {method}")
                self._buffer += chunk
            raw, self._buffer = self._buffer.split(b"\0", 1)
            reply = json.loads(raw)
            if reply.get("id") == self._next_id:
                if "error" in reply:
                    raise RuntimeError(f"{method}: {reply['error']}")
                return reply.get("result", {})

    def close(self) -> None:
        try:
            self.call("Browser.close")
        except (RuntimeError, OSError):
            pass
        try:
            self.process.wait(timeout=10)
        except subprocess.TimeoutExpired:
            self.process.kill()


def _looks_loaded(png: bytes) -> bool:
    """The viewer with data has many colours; the loading screen is nearly uniform."""
    import cv2
    import numpy as np

    image = cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_COLOR)
    if image is None:
        return False
    return len(np.unique(image.reshape(-1, 3)[::7] // 16, axis=0)) > 60


def _serve(session: Path, web_port: int, grpc_port: int, end: float) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-m", "pslog.cli", "view", str(session), "--serve",
         "--web-port", str(web_port), "--grpc-port", str(grpc_port), "--end", str(end)],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
        env={k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")})


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--session", default=str(ROOT / "samples" / "throw.mcap"))
    parser.add_argument("--output", default=str(ROOT / "docs" / "images" / "viewer.png"))
    parser.add_argument("--wait", type=float, default=60.0,
                        help="seconds to let the web viewer load before the capture")
    parser.add_argument("--max-wait", type=float, default=180.0,
                        help="keep waiting up to this long while the page still looks empty")
    parser.add_argument("--size", default="1600x1000", help="window WIDTHxHEIGHT")
    parser.add_argument("--time", "--end", type=float, action="append", dest="times",
                        help="the moment to show, seconds from the session's start (the "
                             "session is served up to it; the viewer opens at the end); "
                             "repeat for several images (default: 0.3, 0.85 and 1.3 s, "
                             "the sample throw rising, bouncing and after the bounce)")
    parser.add_argument("--theme", choices=("light", "dark"), default="light",
                        help="the viewer's colour theme (the page's prefers-color-scheme)")
    parser.add_argument("--web-port", type=int, default=9190)
    parser.add_argument("--grpc-port", type=int, default=9977)
    args = parser.parse_args()

    chromium = shutil.which("chromium") or shutil.which("chromium-browser")
    if chromium is None:
        print("screenshot_viewer: chromium not found (apt-get install chromium)", file=sys.stderr)
        return 1
    width, height = (int(v) for v in args.size.split("x"))
    times = args.times or [0.3, 0.85, 1.3]
    output = Path(args.output)
    failed = 0
    for t in times:
        path = (output if len(times) == 1
                else output.with_name(f"{output.stem}-{t:g}s{output.suffix}"))
        failed += _capture(args, chromium, width, height, t, path)
    return 1 if failed else 0


def _capture(args, chromium: str, width: int, height: int, moment: float,
             output: Path) -> int:
    """Serve the session up to ``moment`` seconds, screenshot the viewer to ``output``;
    returns 0, or 1 when the page never looked loaded."""
    server = _serve(Path(args.session), args.web_port, args.grpc_port, moment)
    browser: _DevTools | None = None
    try:
        for line in server.stdout:  # wait until everything is logged and served
            print(f"  pslog view: {line.rstrip()}")
            if line.startswith("serving"):
                break
        else:
            print("screenshot_viewer: pslog view --serve stopped", file=sys.stderr)
            return 1
        grpc = f"rerun+http://127.0.0.1:{args.grpc_port}/proxy"
        url = f"http://127.0.0.1:{args.web_port}/?url={quote(grpc, safe='')}"
        with tempfile.TemporaryDirectory(ignore_cleanup_errors=True) as user_data:
            browser = _DevTools(chromium, user_data, width, height)
            target = browser.call("Target.createTarget", {"url": "about:blank"})["targetId"]
            session = browser.call("Target.attachToTarget",
                                   {"targetId": target, "flatten": True})["sessionId"]
            browser.call("Emulation.setDeviceMetricsOverride", {
                "width": width, "height": height, "deviceScaleFactor": 1, "mobile": False},
                session)
            browser.call("Emulation.setEmulatedMedia", {"features": [
                {"name": "prefers-color-scheme", "value": args.theme}]}, session)
            browser.call("Page.navigate", {"url": url}, session)
            start = time.monotonic()
            time.sleep(args.wait)
            while True:
                png = base64.b64decode(browser.call(
                    "Page.captureScreenshot", {"format": "png"}, session)["data"])
                waited = time.monotonic() - start
                if _looks_loaded(png) or waited > args.max_wait:
                    break
                print(f"  still loading after {waited:.0f} s; waiting")
                time.sleep(10)
            browser.close()  # before the profile folder goes
            browser = None
        output.parent.mkdir(parents=True, exist_ok=True)
        output.write_bytes(png)
        print(f"wrote {output} ({len(png) / 1e3:.0f} kB, after {waited:.0f} s)")
        return 0 if _looks_loaded(png) else 1
    finally:
        if browser is not None:
            browser.close()
        server.terminate()
        server.wait(timeout=10)


if __name__ == "__main__":
    sys.exit(main())
