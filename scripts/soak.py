#!/usr/bin/env python3
"""Soak: laserlined for a long run against a GigE camera that fails, on a hostile network.

  sudo scripts/soak.py [--minutes 10] [--build build/default] [--rate 100] [--out DIR]

Runs inside a private network namespace (nothing leaves the machine), with the project's
test-only parts from the build tree:
  - the simulated scanner served as a GigE Vision camera over loopback (tests/standins/fake_gige_scanner,
    Aravis's fake camera) losing --lost-per-thousand of its stream packets;
  - laserlined on it (aravis backend, the default detector), the laser on a stand-in GPIO chip
    (tests/standins/gpiochip_shim.cpp, LD_PRELOAD) whose pin changes are logged with their time;
  - the camera killed (SIGKILL) every --outage-every seconds and started again --outage-s later;
  - a malformed LCM message every second on each of the daemon's channels (lengths that lie,
    negative counts, truncated bodies), while laserline-listen and lcm-logger listen.
At the end it prints one summary: crashes, the resident memory over the run (flat or not), how
long the laser stayed on after each outage began against laser.frame_timeout_ms, and the
daemon's own counters from its last status message. Exit status 0 only if every check held.
This is a benchmark-style run, not a test: it takes the time it is given.
"""
import argparse
import os
import random
import signal
import socket
import struct
import subprocess
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
MULTICAST = ("239.255.76.67", 7667)
FRAME_TIMEOUT_MS = 300


def enter_private_network():
    """Re-runs this script under `unshare -n` once; then brings loopback up for multicast."""
    if os.environ.get("LASERLINE_SOAK_NAMESPACE") != "1":
        os.environ["LASERLINE_SOAK_NAMESPACE"] = "1"
        cmd = ["unshare", "-n", sys.executable] + sys.argv
        if os.geteuid() != 0:
            cmd = ["sudo", "-E"] + cmd
        os.execvp(cmd[0], cmd)
    subprocess.run(["ip", "link", "set", "lo", "up", "multicast", "on"], check=True)
    subprocess.run(["ip", "route", "add", "224.0.0.0/4", "dev", "lo"], check=True)


def valid_messages(types_dir):
    """One encoded message of each of the daemon's types, by channel."""
    sys.path.insert(0, types_dir)
    import laserline  # noqa: E402  (lcm-gen's Python types, built with the project)
    image = laserline.image_t()
    image.data = b""
    return {"LASERLINE_PROFILE": laserline.profile_t().encode(),
            "LASERLINE_IMAGE": image.encode(),
            "LASERLINE_STATUS": laserline.status_t().encode()}


def malformed(valid, rng):
    """A message of the right type (its fingerprint intact) whose body lies: a length or count
    set to -1 or 2^31-1, the body cut short, or random bytes after the fingerprint."""
    kind = rng.randrange(3)
    if kind == 0 and len(valid) >= 12:
        at = rng.randrange(8, len(valid) - 3)
        value = rng.choice([-1, 0x7FFFFFFF, -0x80000000])
        return valid[:at] + struct.pack(">i", value) + valid[at + 4:]
    if kind == 1:
        return valid[:rng.randrange(8, len(valid))]
    return valid[:8] + bytes(rng.getrandbits(8) for _ in range(rng.randint(0, 600)))


def send_malformed(sock, seq, valid, rng):
    for channel, message in valid.items():
        packet = (struct.pack(">II", 0x4C433032, seq) + channel.encode() + b"\0" +
                  malformed(message, rng))
        sock.sendto(packet, MULTICAST)


def rss_kb(pid):
    try:
        with open("/proc/%d/status" % pid) as f:
            for line in f:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1])
    except OSError:
        pass
    return None


def read_pins(path):
    """(wall ns, level, event) of every pin change of the stand-in chip."""
    events = []
    try:
        with open(path) as f:
            for line in f:
                parts = line.split()
                if len(parts) >= 5:
                    events.append((int(parts[1]), int(parts[3]), parts[4]))
    except OSError:
        pass
    return events


def last_status(log_path, types_dir):
    sys.path.insert(0, types_dir)
    sys.path.insert(0, os.path.join(ROOT, "tools"))
    from laserline_log_reader import read_events  # noqa: E402
    from laserline import status_t  # noqa: E402
    status = None
    totals = {"regions": 0, "records": 0, "bytes": 0, "first": None, "truncated": False}
    for _, _, channel, data in read_events(log_path, lambda m: None, totals):
        if channel == "LASERLINE_STATUS":
            try:
                status = status_t.decode(data)
            except Exception:  # a malformed message of ours, logged like any other
                pass
    return status


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--minutes", type=float, default=10)
    parser.add_argument("--build", default=os.path.join(ROOT, "build", "default"))
    parser.add_argument("--rate", type=float, default=100, help="camera frame rate, Hz")
    parser.add_argument("--lost-per-thousand", type=float, default=10)
    parser.add_argument("--outage-every", type=float, default=60, help="seconds")
    parser.add_argument("--outage-s", type=float, default=5, help="camera down this long")
    parser.add_argument("--out", default=None, help="keep the run's files here")
    args = parser.parse_args()
    enter_private_network()

    build = os.path.abspath(args.build)
    daemon = os.path.join(build, "daemon", "laserlined")
    scanner = os.path.join(build, "tests", "fake_gige_scanner")
    shim = os.path.join(build, "tests", "libgpiochip_shim.so")
    listen = os.path.join(build, "tools", "laserline-listen")
    types_dir = os.path.join(build, "lcmtypes", "python")
    for path in (daemon, scanner, shim, listen):
        if not os.path.exists(path):
            sys.exit("soak: %s is missing: build the default preset with its tests first" % path)
    out = args.out or tempfile.mkdtemp(prefix="laserline_soak_")
    os.makedirs(out, exist_ok=True)
    pins = os.path.join(out, "pins.log")
    config = os.path.join(out, "soak.yaml")
    status_log = os.path.join(out, "status.lcmlog")
    url = "udpm://%s:%d?ttl=0&recv_buf_size=8388608" % MULTICAST
    with open(config, "w") as f:
        f.write(
            "camera: {backend: aravis, device: SOAK, frame_rate_hz: %g, packet_size: 1400}\n"
            "calibration: {camera: {width: 640, height: 480, fx: 704, fy: 704, cx: 319.5,"
            " cy: 239.5}}\n"
            "laser: {backend: gpiod, chip: gpiochip0, line: 0, mode: on,"
            " frame_timeout_ms: %d}\n"
            "lcm: {url: \"%s\", image_every_n: 10, status_period_s: 1}\n"
            % (args.rate, FRAME_TIMEOUT_MS, url))

    def start_scanner(n):
        return subprocess.Popen(
            [scanner, "--serial", "SOAK", "--width", "640", "--height", "480", "--pins", pins,
             "--lost-per-thousand", str(args.lost_per_thousand)],
            stdout=open(os.path.join(out, "scanner%d.out" % n), "w"), stderr=subprocess.STDOUT)

    env = dict(os.environ, LD_PRELOAD=shim, LASERLINE_GPIO_SHIM_LOG=pins)
    cam = start_scanner(0)
    time.sleep(1.0)
    logger = subprocess.Popen(["lcm-logger", "--channel=LASERLINE_STATUS", "--lcm-url=" + url,
                               "--quiet", "--force", status_log],
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    listener = subprocess.Popen([listen, "--url", url, "--quiet", "3600"],
                                stdout=open(os.path.join(out, "listen.out"), "w"),
                                stderr=subprocess.STDOUT)
    proc = subprocess.Popen([daemon, "--config", config], env=env,
                            stdout=open(os.path.join(out, "daemon.out"), "w"),
                            stderr=subprocess.STDOUT)
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_TTL, 0)
    rng = random.Random(1)
    valid = valid_messages(types_dir)

    start = time.monotonic()
    end = start + args.minutes * 60
    next_outage = start + args.outage_every
    restart_at = None
    outages = []  # (wall ns) when the camera was killed and started again
    rss = []      # (seconds since start, kB)
    seq = 0
    crashed = None
    while time.monotonic() < end:
        now = time.monotonic()
        if proc.poll() is not None:
            crashed = proc.returncode
            break
        if restart_at is None and now >= next_outage:
            outages.append([time.time_ns(), None])
            cam.send_signal(signal.SIGKILL)
            cam.wait()
            restart_at = now + args.outage_s
        elif restart_at is not None and now >= restart_at:
            outages[-1][1] = time.time_ns()
            cam = start_scanner(len(outages))
            restart_at = None
            next_outage = now + args.outage_every - args.outage_s
        send_malformed(sock, seq, valid, rng)
        seq += 1
        kb = rss_kb(proc.pid)
        if kb is not None:
            rss.append((now - start, kb))
        time.sleep(max(0.0, 1.0 - (time.monotonic() - now)))

    if crashed is None:
        proc.send_signal(signal.SIGTERM)
        try:
            proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            proc.kill()
            crashed = "did not stop within 10 s of SIGTERM"
        else:
            if proc.returncode != 0:
                crashed = "exit status %d after SIGTERM" % proc.returncode
    for p in (cam, logger, listener):
        p.send_signal(signal.SIGINT)
    for p in (cam, logger, listener):
        try:
            p.wait(timeout=5)
        except subprocess.TimeoutExpired:
            p.kill()
    listener_failed = listener.returncode not in (0, -signal.SIGINT, 130)

    # The laser in each outage (from the kill to the restart): off within the frame timeout if
    # it was on when the camera died, and never switched on while no frame came.
    events = read_pins(pins)
    off_delays, on_in_outage = [], 0
    for killed, restarted in outages:
        on_at_kill = None
        for t, level, _ in events:
            if t <= killed:
                on_at_kill = level
        if on_at_kill == 1:
            off_delays.append(next(((t - killed) / 1e6 for t, level, _ in events
                                    if t > killed and level == 0), None))
        on_in_outage += sum(1 for t, level, event in events
                            if killed < t < restarted and level == 1 and event == "set")
    left_off = bool(events) and events[-1][1] == 0

    # Memory: the first minute is warm-up (buffers, the detector's history); then flat.
    settled = [kb for t, kb in rss if t >= min(60.0, args.minutes * 30)]
    growth = (settled[-1] - settled[0]) / settled[0] * 100 if len(settled) > 1 else 0.0
    status = last_status(status_log, types_dir) if os.path.exists(status_log) else None

    print("soak: %.1f min at %g Hz, %g/1000 packets lost, %d camera outages of %g s, "
          "%d malformed messages; files in %s"
          % (args.minutes, args.rate, args.lost_per_thousand, len(outages), args.outage_s,
             seq * len(valid), out))
    print("  crashes: %s" % ("none" if crashed is None else crashed))
    refused = ""
    try:
        with open(os.path.join(out, "listen.out")) as f:
            for line in f:
                if "undecodable messages:" in line:
                    refused = ", %s refused as undecodable" % line.split(":")[1].strip()
    except OSError:
        pass
    print("  listener (laserline-listen): %s%s" % (
        "ran to the end" if not listener_failed
        else "ended with status %s" % listener.returncode, refused))
    if settled:
        print("  resident memory after the first minute: %d -> %d kB (%+.2f %%), max %d kB"
              % (settled[0], settled[-1], growth, max(settled)))
    worst = max((d for d in off_delays if d is not None), default=None)
    print("  laser on when the camera died in %d of %d outages; off after (frame_timeout_ms %d): "
          "%s ms%s; switched on while no frame came: %d times"
          % (len(off_delays), len(outages), FRAME_TIMEOUT_MS,
             ", ".join("never" if d is None else "%.0f" % d for d in off_delays) or "-",
             "" if worst is None else " (worst %.0f)" % worst, on_in_outage))
    print("  laser off at the end: %s" % ("yes" if left_off else "NO"))
    if status is not None:
        fields = ["frames_captured", "frames_processed", "frames_dropped", "profiles_published",
                  "camera_reconnects", "camera_missing_packets", "camera_skipped_frames",
                  "camera_timeouts", "grab_timeouts", "grab_errors", "laser_safety_offs",
                  "laser_errors"]
        fields += [f for f in getattr(status, "__slots__", [])
                   if ("bad" in f or "malformed" in f) and f not in fields]
        print("  last status: " + ", ".join("%s %s" % (f, getattr(status, f)) for f in fields
                                            if hasattr(status, f)))
    else:
        print("  last status: none recorded")
    # The frame watchdog looks every few tens of milliseconds; a loaded machine adds a little.
    allowed_ms = FRAME_TIMEOUT_MS + 100
    ok = (crashed is None and not listener_failed and left_off and abs(growth) <= 1.0 and
          on_in_outage == 0 and all(d is not None and d <= allowed_ms for d in off_delays))
    print("soak: %s" % ("every check held" if ok else "FAILED"))
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
