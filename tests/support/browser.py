"""Headless Chromium for the browser tests (tests/pipeline/test_view_html.py,
tests/ply_viewer/test_ply_viewer.py), driven over the DevTools protocol on
--remote-debugging-pipe with the standard library only: one client, so that a fix to the launch
flags or the message loop reaches both tests."""
import contextlib
import json
import os
import shutil
import subprocess
import tempfile
import time


def find_chromium():
    """The first Chromium-family browser on PATH, or None (the tests then skip)."""
    for name in ("chromium", "chromium-browser", "google-chrome"):
        path = shutil.which(name)
        if path:
            return path
    return None


class DevTools:
    """The DevTools protocol over --remote-debugging-pipe: NUL-terminated JSON messages on fds 3/4."""

    def __init__(self, chromium, profile):
        """Starts headless `chromium` with the user data folder `profile`, its pipe on fds 3/4."""
        to_chrome_r, self.to_chrome = os.pipe()
        self.from_chrome, from_chrome_w = os.pipe()

        def child_fds():  # the pipe ends may already be fds 3 or 4: copy them away first
            r, w = os.dup(to_chrome_r), os.dup(from_chrome_w)
            os.dup2(r, 3)
            os.dup2(w, 4)

        args = [chromium, "--headless=new", "--no-sandbox", "--remote-debugging-pipe", "--use-angle=swiftshader",
                "--enable-unsafe-swiftshader", "--no-first-run", "--no-default-browser-check", "--disable-extensions",
                "--disable-background-networking", "--mute-audio", "--hide-scrollbars",
                "--user-data-dir=" + profile, "about:blank"]
        self.proc = subprocess.Popen(args, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                                     stderr=subprocess.DEVNULL, close_fds=False, preexec_fn=child_fds)
        os.close(to_chrome_r)
        os.close(from_chrome_w)
        self.next_id = 0
        self.buffer = b""
        self.events = []
        self.session = None

    def _read_message(self, deadline):
        """The next message from chromium; TimeoutError past `deadline` (time.time())."""
        while b"\0" not in self.buffer:
            if time.time() > deadline:
                raise TimeoutError("no answer from chromium")
            chunk = os.read(self.from_chrome, 1 << 20)
            if not chunk:
                raise RuntimeError("chromium closed the pipe")
            self.buffer += chunk
        raw, self.buffer = self.buffer.split(b"\0", 1)
        return json.loads(raw)

    def call(self, method, params=None, timeout=30, session=True):
        """Sends one command (to the attached page when `session`) and returns its result; the
        events that arrive meanwhile are kept in self.events."""
        self.next_id += 1
        msg = {"id": self.next_id, "method": method, "params": params or {}}
        if session and self.session:
            msg["sessionId"] = self.session
        os.write(self.to_chrome, json.dumps(msg).encode() + b"\0")
        deadline = time.time() + timeout
        while True:
            m = self._read_message(deadline)
            if m.get("id") == self.next_id:
                if "error" in m:
                    raise RuntimeError("%s: %s" % (method, m["error"]))
                return m.get("result", {})
            self.events.append(m)

    def evaluate(self, expression, timeout=30):
        """The value of a JavaScript expression in the page (promises awaited); a page exception raises."""
        r = self.call("Runtime.evaluate", {"expression": expression, "returnByValue": True, "awaitPromise": True},
                      timeout=timeout)
        if "exceptionDetails" in r:
            raise RuntimeError("page exception in %r: %s" % (expression, json.dumps(r["exceptionDetails"])[:800]))
        return r["result"].get("value")

    def errors(self):
        """The console errors, failed assertions, uncaught exceptions and error log entries seen so far."""
        out = []
        for m in self.events:
            p = m.get("params", {})
            if m.get("method") == "Runtime.exceptionThrown":
                out.append("exception: " + json.dumps(p.get("exceptionDetails", {}))[:500])
            elif m.get("method") == "Runtime.consoleAPICalled" and p.get("type") in ("error", "assert"):
                out.append("console.%s: %s" % (p["type"], json.dumps(p.get("args", []))[:500]))
            elif m.get("method") == "Log.entryAdded" and p.get("entry", {}).get("level") == "error":
                out.append("log: " + p["entry"].get("text", "")[:500])
        return out

    def open_page(self, url, width, height, domains=("Runtime", "Log", "Page")):
        """Opens a tab of width x height CSS pixels, attaches this client to it (later calls go to
        the page), enables the event `domains` that errors() and the test read, and loads `url`."""
        target = self.call("Target.createTarget", {"url": "about:blank"}, session=False)["targetId"]
        self.session = self.call("Target.attachToTarget", {"targetId": target, "flatten": True}, session=False)["sessionId"]
        for domain in domains:
            self.call(domain + ".enable")
        self.call("Emulation.setDeviceMetricsOverride",
                  {"width": width, "height": height, "deviceScaleFactor": 1, "mobile": False})
        self.call("Page.navigate", {"url": url})

    def close(self):
        """Closes the browser (killing it after 5 s) and the pipe."""
        try:
            self.call("Browser.close", session=False, timeout=5)
        except Exception:  # noqa: BLE001 - closing anyway
            pass
        try:
            self.proc.wait(timeout=5)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()
        os.close(self.to_chrome)
        os.close(self.from_chrome)


@contextlib.contextmanager
def browser(chromium, prefix):
    """A DevTools client of a fresh `chromium` whose profile is a temporary folder named `prefix`*;
    the browser is closed and the folder removed on leaving, however the test ends."""
    profile = tempfile.mkdtemp(prefix=prefix)
    dt = DevTools(chromium, profile)
    try:
        yield dt
    finally:
        dt.close()
        shutil.rmtree(profile, ignore_errors=True)
