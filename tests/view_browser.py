#!/usr/bin/env python3
"""Opens laserline-view's page in a real headless Chromium driven over the DevTools protocol
(standard library only: a minimal WebSocket client), and reports as JSON on stdout: the console
messages and exceptions at warning level or worse (the browser's own log too: blocked loads,
failed requests), the page's state (body data attributes, the frame canvas's place), the load
time, and two screenshots some seconds apart (PNG files in OUT_DIR).

With --control TOKEN STEPS (laserline-view --allow-control): types the token into the page's
controls, then for each step of STEPS (a JSON list) in turn: types "fields" ({element id: text}),
drags the mouse over the frame from one frame pixel's centre to another's ("drag": [x0, y0, x1,
y1]), presses "click" (a button's id) and waits for the daemon's answer to appear, waits
"settle_s" and takes a screenshot when the step names one ("screenshot": file name). Reports
each step ("control": "steps": the answer's text and class, the exposure's and the region's
fields after it).

usage: view_browser.py URL OUT_DIR [SECONDS_BETWEEN_SCREENSHOTS] [--control TOKEN STEPS]
"""
import base64
import json
import os
import shutil
import socket
import struct
import subprocess
import sys
import tempfile
import time


class DevTools:
    def __init__(self, ws_url):
        assert ws_url.startswith("ws://")
        host_port, path = ws_url[5:].split("/", 1)
        host, port = host_port.rsplit(":", 1)
        self.sock = socket.create_connection((host, int(port)), timeout=30)
        key = base64.b64encode(os.urandom(16)).decode()
        self.sock.sendall((f"GET /{path} HTTP/1.1\r\nHost: {host_port}\r\nUpgrade: websocket\r\n"
                           f"Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\n"
                           "Sec-WebSocket-Version: 13\r\n\r\n").encode())
        response = b""
        while b"\r\n\r\n" not in response:
            chunk = self.sock.recv(4096)
            if not chunk:
                raise RuntimeError("DevTools closed the WebSocket handshake")
            response += chunk
        head, self.buffer = response.split(b"\r\n\r\n", 1)
        if b" 101 " not in head.split(b"\r\n")[0]:
            raise RuntimeError("DevTools refused the WebSocket: " + head.decode(errors="replace"))
        self.next_id = 0
        self.events = []

    def _read(self, n):
        while len(self.buffer) < n:
            chunk = self.sock.recv(1 << 20)
            if not chunk:
                raise RuntimeError("DevTools closed the connection")
            self.buffer += chunk
        data, self.buffer = self.buffer[:n], self.buffer[n:]
        return data

    def _receive(self):
        message = b""
        while True:
            b0, b1 = self._read(2)
            length = b1 & 0x7F
            if length == 126:
                length = struct.unpack(">H", self._read(2))[0]
            elif length == 127:
                length = struct.unpack(">Q", self._read(8))[0]
            payload = self._read(length)
            message += payload
            if b0 & 0x80:
                return json.loads(message)

    def _send(self, text):
        payload = text.encode()
        header = bytes([0x81])
        if len(payload) < 126:
            header += bytes([0x80 | len(payload)])
        elif len(payload) < 1 << 16:
            header += bytes([0x80 | 126]) + struct.pack(">H", len(payload))
        else:
            header += bytes([0x80 | 127]) + struct.pack(">Q", len(payload))
        mask = os.urandom(4)
        self.sock.sendall(header + mask + bytes(b ^ mask[i % 4] for i, b in enumerate(payload)))

    def call(self, method, **params):
        self.next_id += 1
        self._send(json.dumps({"id": self.next_id, "method": method, "params": params}))
        while True:
            message = self._receive()
            if message.get("id") == self.next_id:
                if "error" in message:
                    raise RuntimeError(f"{method}: {message['error']}")
                return message.get("result", {})
            if "method" in message:
                self.events.append(message)

    def wait(self, seconds):
        """Collects events for `seconds`."""
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            self.sock.settimeout(max(0.05, end - time.monotonic()))
            try:
                message = self._receive()
            except (socket.timeout, TimeoutError):
                break
            finally:
                self.sock.settimeout(30)
            if "method" in message:
                self.events.append(message)


def problems(events):
    """Console messages and exceptions at warning level or worse, and the browser's own log."""
    found = []
    for e in events:
        method, p = e["method"], e.get("params", {})
        if method == "Runtime.consoleAPICalled" and p.get("type") in ("error", "warning", "assert"):
            found.append("console." + p["type"] + ": " +
                         " ".join(str(a.get("value", a.get("description", ""))) for a in p.get("args", [])))
        elif method == "Runtime.exceptionThrown":
            d = p.get("exceptionDetails", {})
            found.append("exception: " + d.get("text", "") + " " +
                         str(d.get("exception", {}).get("description", "")))
        elif method == "Log.entryAdded" and p.get("entry", {}).get("level") in ("error", "warning"):
            entry = p["entry"]
            found.append(f"log {entry.get('source')} {entry['level']}: {entry.get('text')} "
                         f"{entry.get('url', '')}")
    return found


def evaluate(page, expression):
    return json.loads(page.call("Runtime.evaluate", expression=expression)["result"]["value"])


def screenshot(page, path):
    data = page.call("Page.captureScreenshot", format="png")["data"]
    with open(path, "wb") as f:
        f.write(base64.b64decode(data))


def drag(page, frame_pixels):
    """Presses the mouse at one camera pixel, moves it in a few steps, releases it at another."""
    place = evaluate(page, "JSON.stringify({rect: document.getElementById('frame')"
                           ".getBoundingClientRect(), geometry: document.getElementById('frame')"
                           ".dataset.geometry})")
    x0, y0, scale, roi_x, roi_y, k = (float(v) for v in place["geometry"].split(","))
    left, top = place["rect"]["left"], place["rect"]["top"]

    def at(fx, fy):  # the camera pixel's centre
        return {"x": left + x0 + (fx + 0.5 - roi_x) / k * scale,
                "y": top + y0 + (fy + 0.5 - roi_y) / k * scale}

    (fx0, fy0, fx1, fy1) = frame_pixels
    page.call("Input.dispatchMouseEvent", type="mousePressed", button="left", clickCount=1,
              **at(fx0, fy0))
    for i in range(1, 5):
        page.call("Input.dispatchMouseEvent", type="mouseMoved", button="left",
                  **at(fx0 + (fx1 - fx0) * i / 4, fy0 + (fy1 - fy0) * i / 4))
    page.call("Input.dispatchMouseEvent", type="mouseReleased", button="left", clickCount=1,
              **at(fx1, fy1))


def run_controls(page, out_dir, token, steps):
    page.call("Runtime.evaluate",
              expression=f"document.getElementById('token').value = {json.dumps(token)};")
    ack_js = "JSON.stringify({acks: document.body.dataset.acks, " \
             "shown: !document.getElementById('controls').hidden, " \
             "text: document.getElementById('ack').textContent, " \
             "class: document.getElementById('ack').className, " \
             "exposure: document.getElementById('exposure').value, " \
             "region: ['roi-x', 'roi-y', 'roi-w', 'roi-h'].map(" \
             "(id) => document.getElementById(id).value).join(',')})"
    results = []
    for number, step in enumerate(steps):
        before = evaluate(page, ack_js)
        for element, text in step.get("fields", {}).items():
            page.call("Runtime.evaluate", expression=(
                f"document.getElementById({json.dumps(element)}).value = {json.dumps(text)};"))
        if "drag" in step:
            drag(page, step["drag"])
        answer = evaluate(page, ack_js)
        if "click" in step:
            page.call("Runtime.evaluate", expression=(
                f"document.getElementById({json.dumps(step['click'])}).click();"))
            deadline = time.monotonic() + 10
            while time.monotonic() < deadline:
                page.wait(0.05)
                answer = evaluate(page, ack_js)
                if answer.get("acks") != before.get("acks"):
                    break
        if step.get("settle_s"):
            page.wait(step["settle_s"])
        answer = {"step": number, **answer}
        if "screenshot" in step:
            answer["screenshot"] = os.path.join(out_dir, step["screenshot"])
            screenshot(page, answer["screenshot"])
        results.append(answer)
    return {"shown": results[-1]["shown"] if results else False, "steps": results}


def main():
    args = sys.argv[1:]
    control = None
    if "--control" in args:
        at = args.index("--control")
        control = args[at + 1:at + 3]  # the token, the steps
        del args[at:at + 3]
    url, out_dir = args[0], args[1]
    between_s = float(args[2]) if len(args) > 2 else 3.0
    chromium = shutil.which("chromium")
    if chromium is None:
        print(json.dumps({"skip": "chromium is not installed (scripts/install-deps.sh installs it)"}))
        return 0
    profile = tempfile.mkdtemp(prefix="laserline_view_chromium_")
    browser = subprocess.Popen(
        [chromium, "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync",
         "--disable-dev-shm-usage", "--hide-scrollbars", "--window-size=1300,940",
         "--remote-debugging-port=0", "--remote-debugging-address=127.0.0.1",
         f"--user-data-dir={profile}", "about:blank"],
        stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    try:
        port_file = os.path.join(profile, "DevToolsActivePort")
        deadline = time.monotonic() + 30
        while not os.path.exists(port_file) or os.path.getsize(port_file) == 0:
            if browser.poll() is not None or time.monotonic() > deadline:
                raise RuntimeError("chromium did not open its DevTools port: " +
                                   browser.stderr.read().decode(errors="replace")[-2000:])
            time.sleep(0.1)
        with open(port_file) as f:
            port, browser_path = f.read().split("\n")[:2]
        # A page target: ask the browser for a new one.
        browser_tools = DevTools(f"ws://127.0.0.1:{port}{browser_path}")
        target = browser_tools.call("Target.createTarget", url="about:blank")["targetId"]
        page = DevTools(f"ws://127.0.0.1:{port}/devtools/page/{target}")
        for domain in ("Runtime", "Log", "Page", "Network"):
            page.call(domain + ".enable")
        page.call("Emulation.setDeviceMetricsOverride", width=1300, height=940,
                  deviceScaleFactor=1, mobile=False)
        started = time.monotonic()
        page.call("Page.navigate", url=url)
        load_s = None
        while time.monotonic() - started < 20:
            page.wait(0.1)
            if any(e["method"] == "Page.loadEventFired" for e in page.events):
                load_s = time.monotonic() - started
                break
        page.wait(3.0)  # the stream's first events, a frame, a status
        state_js = "JSON.stringify(Object.assign({}, document.body.dataset, " \
                   "{rect: document.getElementById('frame').dataset.rect, " \
                   "status: document.getElementById('status').innerText, " \
                   "frame_info: document.getElementById('frame-info').textContent}))"
        first = json.loads(page.call("Runtime.evaluate", expression=state_js)["result"]["value"])
        shots = []
        for i in range(2):
            if i > 0:
                page.wait(between_s)
            data = page.call("Page.captureScreenshot", format="png")["data"]
            path = os.path.join(out_dir, f"view_{i + 1}.png")
            with open(path, "wb") as f:
                f.write(base64.b64decode(data))
            shots.append(path)
        second = json.loads(page.call("Runtime.evaluate", expression=state_js)["result"]["value"])
        report = {"load_s": load_s, "first": first, "second": second, "screenshots": shots}
        if control is not None:
            report["control"] = run_controls(page, out_dir, control[0], json.loads(control[1]))
        report["problems"] = problems(page.events)
        print(json.dumps(report))
        return 0
    finally:
        browser.terminate()
        try:
            browser.wait(10)
        except subprocess.TimeoutExpired:
            browser.kill()
            browser.wait()
        shutil.rmtree(profile, ignore_errors=True)


if __name__ == "__main__":
    sys.exit(main())
