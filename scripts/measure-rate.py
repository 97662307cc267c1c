#!/usr/bin/python3
"""Finds the highest frame rate the whole daemon sustains: laserlined with the `memory` camera
(frames rendered by the simulator at start, delivered at camera.memory.rate_hz) is run at each rate
in turn, and its own status_t (LCM over UDP in a private network namespace) says what held:
frames, drops, latency. A rate holds when no frame was lost anywhere (camera ring full, frames
due while the camera thread was late, profile ring full) and arrival->published p99 over the run
is within --p99-ms. The steps stop at the first rate that does not hold.

  scripts/measure-rate.py                          # 2048x1536 background, 20 s per rate
  scripts/measure-rate.py --rates 250 --seconds 60 # one rate, as long as asked
  scripts/measure-rate.py --detector fir --width 1280 --height 1024 --rates 200,400,600

The p99 over the run is the daemon's own (its exit line, a 10 us histogram of every frame); the
per-period figures come from status_t, one a second. Needs the build (laserlined, the generated
Python types) and `unshare` (a user namespace when not root).
"""
import argparse
import os
import re
import socket
import statistics
import struct
import subprocess
import sys
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
GROUP, PORT = "239.255.76.67", 7667
SHORT_MESSAGE = 0x4C433032  # LCM's "LC02": a whole message in one datagram

CONFIG = """\
camera:
  backend: memory
  frame_rate_hz: {nominal}
  timeout_ms: 1000
  memory: {{frames: {frames}, rate_hz: {rate}, duration_s: {seconds}}}
  sim: {{tilt_y_deg: 8, distance_m: 1.2, texture_contrast: 0.6, ambient: 150, laser_peak: 110,
        noise_sigma: 2.0, sway_m: 0.01, sway_deg: 0.3, scan_rate_deg_s: 10,
        scan_amplitude_deg: 10}}
calibration:
  camera: {{width: {width}, height: {height}, fx: {f}, fy: {f}, cx: {cx}, cy: {cy},
           distortion: [0, 0, 0, 0, 0]}}
  laser: {{baseline_m: 0.25, angle_deg: 80, sheet_width_m: 0.003}}
laser: {{backend: sim, mode: {laser}}}
detector: {{name: {detector}}}
realtime: {{enabled: {realtime}}}
lcm: {{url: "udpm://{group}:{port}?ttl=0", image_every_n: {image_every_n}}}
"""


def enter_private_network():
    """Re-runs this script in a private network namespace with multicast on loopback."""
    if os.environ.get("LASERLINE_MEASURE_NETNS") == "1":
        for command in (["ip", "link", "set", "lo", "up", "multicast", "on"],
                        ["ip", "route", "add", "224.0.0.0/4", "dev", "lo"]):
            subprocess.run(command, check=True)
        return
    env = dict(os.environ, LASERLINE_MEASURE_NETNS="1")
    unshare = ["unshare", "-n"] if os.geteuid() == 0 else ["unshare", "-rn"]
    try:
        os.execvpe(unshare[0], unshare + [sys.executable] + sys.argv, env)
    except OSError as e:
        sys.exit("measure-rate: cannot make a private network namespace with %s: %s"
                 % (" ".join(unshare), e))


def thread_cpu_seconds(pid):
    """{thread name: CPU seconds so far} of a running process, from /proc."""
    seconds = {}
    tick = os.sysconf("SC_CLK_TCK")
    try:
        tasks = os.listdir("/proc/%d/task" % pid)
    except OSError:
        return seconds
    for tid in tasks:
        try:
            with open("/proc/%d/task/%s/stat" % (pid, tid)) as f:
                stat = f.read()
        except OSError:
            continue
        name = stat[stat.index("(") + 1:stat.rindex(")")]
        fields = stat[stat.rindex(")") + 2:].split()
        seconds[name] = seconds.get(name, 0) + (int(fields[11]) + int(fields[12])) / tick
    return seconds


def steal_ms():
    """Time the hypervisor gave this virtual machine's CPUs to others, so far (0 on bare metal)."""
    with open("/proc/stat") as f:
        fields = f.readline().split()
    return int(fields[8]) * 1000 / os.sysconf("SC_CLK_TCK") if len(fields) > 8 else 0


def status_socket():
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM, socket.IPPROTO_UDP)
    s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 8 << 20)
    s.bind(("", PORT))
    membership = struct.pack("4s4s", socket.inet_aton(GROUP), socket.inet_aton("127.0.0.1"))
    s.setsockopt(socket.IPPROTO_IP, socket.IP_ADD_MEMBERSHIP, membership)
    s.settimeout(0.2)
    return s


def run_rate(args, rate, status_t):
    """Runs the daemon at `rate` for args.seconds; returns what held."""
    scale = args.width / 1280.0
    # The daemon's latency windows and per-frame budget follow memory.rate_hz; at rate 0 (as fast
    # as taken) camera.frame_rate_hz, its highest.
    nominal = min(rate, 1000) if rate > 0 else 1000
    config = CONFIG.format(nominal=nominal, frames=args.frames, rate=rate, seconds=args.seconds,
                           width=args.width, height=args.height,
                           f=1400 * scale, cx=(args.width - 1) / 2, cy=(args.height - 1) / 2,
                           laser=args.laser_mode, detector=args.detector,
                           realtime="true" if args.realtime else "false", group=GROUP,
                           port=PORT, image_every_n=args.image_every_n)
    with tempfile.TemporaryDirectory(prefix="laserline-rate-") as tmp:
        path = os.path.join(tmp, "rate.yaml")
        with open(path, "w") as f:
            f.write(config)
        sock = status_socket()
        output = open(os.path.join(tmp, "laserlined.log"), "w+")
        daemon = subprocess.Popen([args.laserlined, "--config", path], stdout=output,
                                  stderr=subprocess.STDOUT)
        statuses = []
        threads, next_sample = {}, 0
        load_before, steal_before = os.getloadavg()[0], steal_ms()
        while True:
            if time.monotonic() >= next_sample:
                # CPU time only grows: the largest seen is each thread's over the run, also
                # for threads that ended before the last sample.
                for name, cpu in thread_cpu_seconds(daemon.pid).items():
                    threads[name] = max(cpu, threads.get(name, 0))
                next_sample = time.monotonic() + 0.5
            try:
                data = sock.recv(1 << 17)
            except socket.timeout:
                if daemon.poll() is not None:
                    break
                continue
            if len(data) < 8 or struct.unpack_from(">I", data)[0] != SHORT_MESSAGE:
                continue  # a fragment of a large message: profiles and raw frames
            end = data.index(b"\0", 8)
            if data[8:end] != b"LASERLINE_STATUS":
                continue
            statuses.append(status_t.decode(data[end + 1:]))
        sock.close()
        output.seek(0)
        log = output.read()
        output.close()
    if daemon.returncode != 0 or not statuses:
        sys.exit("measure-rate: laserlined failed at %s frames/s (exit %s):\n%s"
                 % (rate, daemon.returncode, log))
    last = statuses[-1]
    stopped = re.search(r"arrival->published p50 ([\d.]+) ms p99 ([\d.]+) ms max ([\d.]+) ms", log)
    run_p50, run_p99, run_max = (float(x) for x in stopped.groups()) if stopped else (0, 0, 0)
    periods = [s for s in statuses if s.latency_samples > 0]
    lost = last.frames_dropped + last.camera_skipped_frames + last.profiles_dropped
    seconds = last.uptime_us * 1e-6
    result = {
        "rate": rate,
        "achieved": last.frames_processed / seconds if seconds > 0 else 0,
        "load": (load_before + os.getloadavg()[0]) / 2,
        "steal": steal_ms() - steal_before,
        "threads": ", ".join("%s %.0f%%" % (name, 100 * cpu / seconds)
                             for name, cpu in sorted(threads.items(), key=lambda t: -t[1])
                             if seconds > 0 and cpu / seconds >= 0.02),
        "seconds": seconds,
        "frames": last.frames_processed,
        "lost": lost,
        "ring_full": last.frames_dropped,
        "late": last.camera_skipped_frames,
        "over_budget": last.frames_over_budget,
        "p50": run_p50,
        "p99": run_p99,
        "max": run_max,
        "period_p99_median":
            statistics.median(s.pipeline_p99_ms for s in periods) if periods else 0,
        "period_p99_worst": max((s.pipeline_p99_ms for s in periods), default=0),
        "cpu": statistics.median(s.cpu_percent for s in periods) if periods else 0,
    }
    # rate 0 (as fast as the frame path takes them) cannot lose frames: it measures throughput.
    result["holds"] = lost == 0 and run_p99 <= args.p99_ms and last.frames_processed > 0
    return result


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--build", default=os.path.join(ROOT, "build", "default"))
    parser.add_argument("--width", type=int, default=2048)
    parser.add_argument("--height", type=int, default=1536)
    parser.add_argument("--detector", default="background",
                        choices=["maxvalue", "fir", "background", "backprojection"])
    parser.add_argument("--rates", default="100,150,200,250,300,350,400,450,500",
                        help="frames/s to try, ascending, comma-separated; 0: as fast as the "
                        "frame path takes them (its throughput, nothing lost by design)")
    parser.add_argument("--seconds", type=float, default=20, help="per rate")
    parser.add_argument("--frames", type=int, default=16, help="frames held (each lit and unlit)")
    parser.add_argument("--p99-ms", type=float, default=8.0,
                        help="arrival->published p99 a rate must stay within")
    parser.add_argument("--laser-mode", default="on", choices=["on", "alternate"])
    parser.add_argument("--image-every-n", type=int, default=30,
                        help="raw frames published (the daemon's default: every 30th, JPEG)")
    parser.add_argument("--realtime", action="store_true",
                        help="camera and worker threads SCHED_FIFO (needs the privilege)")
    args = parser.parse_args()
    args.laserlined = os.path.join(args.build, "daemon", "laserlined")
    types = os.path.join(args.build, "lcmtypes", "python")
    if not os.access(args.laserlined, os.X_OK) or not os.path.isdir(types):
        sys.exit("measure-rate: build laserlined and laserline_lcmtypes_python in %s first"
                 % args.build)
    rates = [float(r) for r in args.rates.split(",")]
    enter_private_network()
    sys.path.insert(0, types)
    from laserline import status_t  # noqa: E402 (generated at build time)

    print("laserlined, memory camera %dx%d, detector %s, laser %s, raw frames every %d, %g s a "
          "rate, %s, p99 target %g ms"
          % (args.width, args.height, args.detector, args.laser_mode, args.image_every_n,
             args.seconds, time.strftime("%Y-%m-%d", time.gmtime()), args.p99_ms))
    print("| frames/s asked | processed (per s) | lost (ring full, late) | over budget | "
          "arrival->published p50 / p99 / max ms | p99 per second: median / worst ms | "
          "CPU % of a core, by thread | load average | CPU stolen by the host, ms | holds |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    best = None
    for rate in rates:
        r = run_rate(args, rate, status_t)
        if rate == 0:  # throughput, not a rate to hold
            print("| 0 (as fast as taken) | %d (%.1f) | - | %d | %.2f / %.2f / %.2f | %.2f / %.2f "
                  "| %.0f: %s | %.1f | %.0f | - |"
                  % (r["frames"], r["achieved"], r["over_budget"], r["p50"], r["p99"], r["max"],
                     r["period_p99_median"], r["period_p99_worst"], r["cpu"], r["threads"],
                     r["load"], r["steal"]), flush=True)
            continue
        print("| %s | %d (%.1f) | %d (%d, %d) | %d | %.2f / %.2f / %.2f | %.2f / %.2f | %.0f: %s "
              "| %.1f | %.0f | %s |"
              % ("%g" % rate if rate > 0 else "0 (as fast as taken)", r["frames"], r["achieved"],
                 r["lost"], r["ring_full"], r["late"], r["over_budget"], r["p50"], r["p99"],
                 r["max"], r["period_p99_median"], r["period_p99_worst"], r["cpu"], r["threads"],
                 r["load"], r["steal"], "yes" if r["holds"] else "no"), flush=True)
        if not r["holds"]:
            break
        best = rate
    if best is None:
        print("maximum sustainable rate: below %g frames/s" % min(r for r in rates if r > 0))
        return 1
    print("maximum sustainable rate: %g frames/s (the highest tried that held)" % best)
    return 0


if __name__ == "__main__":
    sys.exit(main())
