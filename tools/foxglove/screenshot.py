"""Screenshot of a bendsense MCAP opened in Foxglove Studio (docs/img/foxglove.png).

Foxglove Studio's open-source web app, ``@foxglove/studio-base`` 1.48.0 from npm (its
``assets/index.js`` is the whole app as one UMD bundle, React left out), hosted by
``index.html`` + ``app.js`` here with the layout of ``layout.js``; the MCAP is served
on 127.0.0.1 with HTTP range requests (Foxglove's "remote file" source) and Debian's
chromium, driven by Playwright, takes the picture after seeking to ``--at`` of the
recording. See docs/formats.md, "ROS 2 messages in MCAP", for the steps.

Usage: python screenshot.py FILE.mcap OUT.png [--at 0.25] [--chromium /usr/bin/chromium]
(run in this directory, after the three ``npm pack`` of the docs).
"""

import argparse
import http.server
import re
import shutil
import tempfile
import threading
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent


class RangeHandler(http.server.SimpleHTTPRequestHandler):
    """Static files with ``Range: bytes=a-b`` answered by 206 (Foxglove reads MCAP files by ranges)."""

    def end_headers(self):
        """Announce range support with every answer."""
        self.send_header("Accept-Ranges", "bytes")
        super().end_headers()

    def do_GET(self):  # noqa: N802 (the http.server name)
        """Answer a range request with 206 and the bytes asked for; anything else as usual."""
        m = re.match(r"bytes=(\d+)-(\d*)$", self.headers.get("Range", ""))
        path = Path(self.translate_path(self.path))
        if not m or not path.is_file():
            return super().do_GET()
        size = path.stat().st_size
        start, end = int(m.group(1)), min(int(m.group(2) or size - 1), size - 1)
        with open(path, "rb") as fh:
            fh.seek(start)
            data = fh.read(end - start + 1)
        self.send_response(206)
        self.send_header("Content-Type", "application/octet-stream")
        self.send_header("Content-Range", f"bytes {start}-{end}/{size}")
        self.send_header("Content-Length", str(len(data)))
        self.end_headers()
        self.wfile.write(data)

    def log_message(self, *args):
        """Quiet: no line per request."""


def main():
    """Serve the app and the MCAP, open it in chromium, seek and take the screenshot."""
    from playwright.sync_api import sync_playwright

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("mcap", type=Path)
    ap.add_argument("out", type=Path)
    ap.add_argument("--at", type=float, default=0.25, help="Where to seek, as a fraction of the recording.")
    ap.add_argument("--chromium", default=shutil.which("chromium") or "/usr/bin/chromium")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        site = Path(tmp)
        for name in ("index.html", "app.js", "layout.js"):
            shutil.copy(HERE / name, site / name)
        shutil.copytree(HERE / "foxglove-studio-base-1.48.0" / "package" / "assets", site / "assets")
        shutil.copy(HERE / "react-17.0.2" / "package" / "umd" / "react.production.min.js", site)
        shutil.copy(HERE / "react-dom-17.0.2" / "package" / "umd" / "react-dom.production.min.js", site)
        shutil.copy(args.mcap, site / "bendsense.mcap")
        server = http.server.ThreadingHTTPServer(
            ("127.0.0.1", 0), lambda *a: RangeHandler(*a, directory=str(site)))
        threading.Thread(target=server.serve_forever, daemon=True).start()
        base = f"http://127.0.0.1:{server.server_port}"
        url = f"{base}/index.html?ds=remote-file&ds.url={base}/bendsense.mcap&layoutId=bendsense"
        width, height = 1600, 1000
        try:
            with sync_playwright() as p:
                browser = p.chromium.launch(executable_path=args.chromium, args=["--no-sandbox"])
                page = browser.new_page(viewport={"width": width, "height": height})
                page.goto(url)
                page.get_by_text("/bendsense/wrench", exact=True).first.wait_for(timeout=60_000)
                time.sleep(8)  # the plots load the whole file
                page.mouse.click(10 + args.at * (width - 20), 943)  # the playback scrubber
                page.mouse.move(200, 700)  # no hover tooltip in the picture
                time.sleep(5)
                page.screenshot(path=str(args.out))
                browser.close()
        finally:
            server.shutdown()
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
