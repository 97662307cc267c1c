#!/usr/bin/env python3
"""Read a dive recorded with lcm-logger and summarise or export what laserlined published.

Decodes with the Python types lcm-gen makes from lcmtypes/ (package `laserline`); Debian ships no
LCM Python module and none is needed: the log format is read here and the generated types decode
the messages by themselves.

  laserline-log-reader dive.lcmlog                      # summary per channel
  laserline-log-reader dive.lcmlog --points points.csv  # every profile point as CSV
  laserline-log-reader dive.lcmlog --types build/default/lcmtypes/python   # types not installed

A damaged region of the log is reported with its byte offsets and skipped; reading resumes at the
next sync word that begins a whole event. A message that does not decode, or whose size fields do
not match its bytes, is reported in one line and skipped. The exit status is 1 when anything was
damaged, cut short or undecodable (the point is to read the whole log), else 0.
"""
import argparse
import csv
import math
import struct
import sys

EVENT_MARKER = 0xEDA1DA01
HEADER = struct.Struct(">IqqII")  # marker, event number, timestamp, channel length, data length
MAX_CHANNEL = 256


class NotALogError(Exception):
    """The file holds no LCM event at all: another kind of file."""


def read_events(path, report, totals):
    """Yields (event number, timestamp, channel, data); damage goes to report(message) and is
    added up in totals (regions, records, bytes, first offset)."""
    with open(path, "rb") as f:
        blob = f.read()
    marker = struct.pack(">I", EVENT_MARKER)
    if not blob:
        raise NotALogError("empty file, not an LCM log")
    if marker not in blob:
        raise NotALogError("not an LCM log (none of its %d bytes is an event marker %08X)"
                           % (len(blob), EVENT_MARKER))
    pos, good_end = 0, 0
    failed_markers = 0

    def note(start, end):
        totals["regions"] += 1
        totals["records"] += max(1, failed_markers)
        totals["bytes"] += end - start
        if totals["first"] is None:
            totals["first"] = start
    while pos < len(blob):
        event = None
        if pos + HEADER.size <= len(blob):
            magic, number, utime, clen, dlen = HEADER.unpack_from(blob, pos)
            end = pos + HEADER.size + clen + dlen
            if magic == EVENT_MARKER and 0 < clen <= MAX_CHANNEL and end <= len(blob):
                channel = blob[pos + HEADER.size:pos + HEADER.size + clen].decode("utf-8", "replace")
                event = (number, utime, channel, blob[pos + HEADER.size + clen:end])
        if event is None:
            if blob.startswith(marker, pos):
                failed_markers += 1
            nxt = blob.find(marker, pos + 1)
            pos = len(blob) if nxt < 0 else nxt
            continue
        if pos > good_end:
            note(good_end, pos)
            report("%s: bytes %d..%d are damaged (%d bytes, %d records); skipped, reading resumes "
                   "at event %d" % (path, good_end, pos - 1, pos - good_end, max(1, failed_markers),
                                     event[0]))
        failed_markers = 0
        yield event
        pos = good_end = end
    if good_end < len(blob):
        note(good_end, len(blob))
        totals["truncated"] = True
        report("%s: the log ends inside an event or in damage: the last %d bytes (from byte %d) "
               "are not a complete event (recording cut short?); ignored"
               % (path, len(blob) - good_end, good_end))


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("log", help="an LCM log file (lcm-logger)")
    parser.add_argument("--types", help="directory holding the generated `laserline` package")
    parser.add_argument("--points", metavar="CSV", help="write every profile point to this file")
    parser.add_argument("--profile-channel", default="LASERLINE_PROFILE")
    parser.add_argument("--status-channel", default="LASERLINE_STATUS")
    parser.add_argument("--image-channel", default="LASERLINE_IMAGE")
    parser.add_argument("--calibration-channel", default="LASERLINE_CALIBRATION")
    args = parser.parse_args()
    if args.types:
        sys.path.insert(0, args.types)
    try:
        import laserline
    except ImportError:
        sys.exit("laserline-log-reader: the generated Python types (package `laserline`) are not "
                 "installed; pass --types DIR (e.g. build/default/lcmtypes/python)")

    problems = []
    shown = 20  # lines of problems shown; the rest are counted (a log damaged all over)

    def report(message):
        problems.append(message)
        if len(problems) <= shown:
            print("laserline-log-reader: " + message, file=sys.stderr)
        elif len(problems) == shown + 1:
            print("laserline-log-reader: %s: further problems are counted, not shown" % args.log,
                  file=sys.stderr)

    decoders = {args.profile_channel: laserline.profile_t, args.status_channel: laserline.status_t,
                args.image_channel: laserline.image_t,
                args.calibration_channel: laserline.calibration_t}
    profiles, statuses, images, other = [], [], [], {}
    calibrations = {}  # calibration_id -> its last calibration_t
    calibration_count = 0
    profile_calibrations = set()  # the calibration ids the profiles name
    first_utime = last_utime = None
    try:
        points_out = open(args.points, "w", newline="") if args.points else None
    except OSError as e:
        sys.exit("laserline-log-reader: --points %s: %s" % (args.points, e.strerror or e))
    writer = csv.writer(points_out) if points_out else None
    if writer:
        # u, v: the point's epipolar line and position along it (the column and row for the usual
        # mounting); pixel_x, pixel_y: the frame pixel; x, y, z: metres in the camera frame.
        writer.writerow(["sequence", "utime", "u", "v", "pixel_x", "pixel_y", "snr_db", "segment",
                         "valid", "x", "y", "z"])
    events = 0
    totals = {"regions": 0, "records": 0, "bytes": 0, "first": None, "truncated": False}
    instances = {}  # channel -> instance ids seen (two daemons on one channel show two)
    try:
        for number, utime, channel, data in read_events(args.log, report, totals):
            events += 1
            first_utime = utime if first_utime is None else first_utime
            last_utime = utime
            decoder = decoders.get(channel)
            if decoder is None:
                other[channel] = other.get(channel, 0) + 1
                continue
            try:
                msg = decoder.decode(data)
                # A size field that does not match the bytes (a string, num_points or an image's
                # size) decodes without a word in lcm-gen's Python: encoded again it differs.
                encoded = len(msg.encode())
            except Exception as e:  # pylint: disable=broad-except
                report("%s: event %d on %s does not decode as %s (%s: %s); skipped"
                       % (args.log, number, channel, decoder.__name__, type(e).__name__, e))
                continue
            if encoded != len(data):
                report("%s: event %d on %s: its size fields do not match its %d bytes (they "
                       "account for %d); skipped" % (args.log, number, channel, len(data), encoded))
                continue
            if decoder is not laserline.image_t:
                ids = instances.setdefault(channel, set())
                ids.add(msg.instance_id)
                if len(ids) == 2:
                    report("%s: %s: messages from two daemons (instance ids %s); two laserlined "
                           "published on the same channels"
                           % (args.log, channel, " and ".join("%016x" % (i & (2**64 - 1))
                                                              for i in sorted(ids))))
            if decoder is laserline.profile_t:
                profiles.append((msg.sequence, msg.num_points))
                profile_calibrations.add(msg.calibration_id & (2**64 - 1))
                if writer:
                    o, l, a = msg.search_origin, msg.search_line_step, msg.search_along
                    for p in msg.points:
                        pixel = (o[0] + p.u * l[0] + p.v * a[0], o[1] + p.u * l[1] + p.v * a[1])
                        writer.writerow([msg.sequence, msg.utime, p.u, "%.3f" % p.v,
                                         "%.3f" % pixel[0], "%.3f" % pixel[1],
                                         "%.1f" % p.snr_db, p.segment, int(p.valid)] +
                                        ["" if math.isnan(c) else "%.5f" % c for c in p.xyz])
            elif decoder is laserline.status_t:
                statuses.append(msg)
            elif decoder is laserline.calibration_t:
                calibration_count += 1
                calibrations[msg.calibration_id & (2**64 - 1)] = msg
            else:
                images.append((msg.width, msg.height, msg.compression))
    except OSError as e:
        sys.exit("laserline-log-reader: %s: %s" % (args.log, e.strerror or e))
    except NotALogError as e:
        sys.exit("laserline-log-reader: %s: %s" % (args.log, e))
    finally:
        if points_out:
            points_out.close()
    if len(problems) > shown:
        print("laserline-log-reader: %s: %d problems in all" % (args.log, len(problems)),
              file=sys.stderr)
    if totals["regions"]:
        shown = len(problems) + 1  # the summary is always shown
        report("%s: %d damaged region%s (%d records, %d bytes skipped, the first at byte %d)%s"
               % (args.log, totals["regions"], "" if totals["regions"] == 1 else "s",
                  totals["records"], totals["bytes"], totals["first"],
                  "; the file ends inside an event (recording cut short?)"
                  if totals["truncated"] else ""))

    seconds = (last_utime - first_utime) * 1e-6 if events else 0.0
    print("%s: %d events over %.1f s" % (args.log, events, seconds))
    if profiles:
        seqs = [s for s, _ in profiles]
        missing = sum(max(0, b - a - 1) for a, b in zip(seqs, seqs[1:]))
        mean_points = sum(n for _, n in profiles) / len(profiles)
        print("%s: %d profiles, sequence %d..%d (%d missing), %.1f points per profile"
              % (args.profile_channel, len(profiles), seqs[0], seqs[-1], missing, mean_points))
    else:
        print("%s: no profiles" % args.profile_channel)
    if statuses:
        s = statuses[-1]
        print("%s: %d messages; last: camera %s, %d frames processed, %d dropped, laser %s, "
              "CPU %.0f%%, %d bad input messages, %d bad frames, raw frames %d published, "
              "%d dropped, instance %016x"
              % (args.status_channel, len(statuses), s.camera_state, s.frames_processed,
                 s.frames_dropped, "on" if s.laser_on else "off", s.cpu_percent, s.bad_messages,
                 s.bad_frames, s.images_published, s.images_dropped, s.instance_id & (2**64 - 1)))
    if calibrations:
        print("%s: %d messages, calibration %s" % (
            args.calibration_channel, calibration_count,
            ", ".join("%016x (%dx%d, fx %g, fy %g, cx %g, cy %g, plane %s)"
                      % (i, c.width, c.height, c.fx, c.fy, c.cx, c.cy,
                         " ".join("%g" % v for v in c.laser_plane))
                      for i, c in sorted(calibrations.items()))))
    else:
        print("%s: no calibration" % args.calibration_channel)
    if calibrations and profile_calibrations and profile_calibrations != set(calibrations):
        report("%s: the profiles name calibration %s, %s carries %s" % (
            args.log, ", ".join("%016x" % i for i in sorted(profile_calibrations)),
            args.calibration_channel,
            ", ".join("%016x" % i for i in sorted(calibrations))))
    if images:
        names = {0: "none", 1: "png", 2: "jpeg", 3: "zlib"}
        w, h, c = images[-1]
        print("%s: %d raw frames, last %dx%d (%s)"
              % (args.image_channel, len(images), w, h, names.get(c, str(c))))
    for channel, count in sorted(other.items()):
        print("%s: %d events (not a laserline channel)" % (channel, count))
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
