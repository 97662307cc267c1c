#!/usr/bin/env python3
"""Change a setting of a running laserlined from Python, as laserline-ctl does.

An example for scripts on the vehicle: the command (laserline.command_t) is encoded with the Python
types lcm-gen makes from lcmtypes/ (package `laserline`) and sent as one LCM UDP multicast
datagram; the answer (laserline.command_ack_t with the same id) is received the same way. Debian
ships no LCM Python module and none is needed for messages this small.

  laserline_ctl.py set exposure_us 1500
  laserline_ctl.py get
  laserline_ctl.py set detector.roi 100,50,400,300    # "full": the whole frame again
  laserline_ctl.py laser off
  laserline_ctl.py --types build/default/lcmtypes/python get     # types not installed

Exit status: 0 accepted, 1 refused, 2 usage, 3 no answer in time.
"""
import argparse
import os
import random
import socket
import struct
import sys
import time
import urllib.parse

SHORT_MAGIC = 0x4C433032  # "LC02": an LCM message in one datagram
MAX_DATAGRAM = 65507


def parse_url(url):
    """(group, port, ttl) of an udpm:// LCM URL."""
    parts = urllib.parse.urlsplit(url)
    if parts.scheme != "udpm" or not parts.hostname:
        raise ValueError("--lcm-url: only udpm://GROUP:PORT URLs, got '%s'" % url)
    ttl = int(urllib.parse.parse_qs(parts.query).get("ttl", ["0"])[0])
    return parts.hostname, parts.port or 7667, ttl


def datagram(channel, payload, sequence):
    return struct.pack(">II", SHORT_MAGIC, sequence) + channel.encode() + b"\0" + payload


def receiver(group, port):
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM, socket.IPPROTO_UDP)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    if hasattr(socket, "SO_REUSEPORT"):
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEPORT, 1)
    sock.bind(("", port))
    membership = socket.inet_aton(group) + socket.inet_aton("0.0.0.0")
    sock.setsockopt(socket.IPPROTO_IP, socket.IP_ADD_MEMBERSHIP, membership)
    return sock


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("words", nargs="+", help="set NAME VALUE | get | laser MODE")
    parser.add_argument("--lcm-url", default="udpm://239.255.76.67:7667?ttl=0")
    parser.add_argument("--channel", default="LASERLINE_COMMAND")
    parser.add_argument("--ack-channel", help="default: the channel + _ACK")
    parser.add_argument("--token", default="")
    parser.add_argument("--timeout", type=float, default=3.0)
    parser.add_argument("--types", help="directory holding the generated `laserline` package")
    args = parser.parse_args()
    words = args.words
    if words[0] == "set" and len(words) == 3:
        name, value = words[1], words[2]
    elif words == ["get"]:
        name, value = "get", ""
    elif words[0] == "laser" and len(words) == 2:
        name, value = "laser.mode", words[1]
    else:
        parser.error("expected set NAME VALUE, get or laser MODE")
    if args.types:
        sys.path.insert(0, args.types)
    try:
        import laserline
    except ImportError:
        sys.exit("laserline_ctl.py: the generated Python types (package `laserline`) are not "
                 "installed; pass --types DIR (e.g. build/default/lcmtypes/python)")
    try:
        group, port, ttl = parse_url(args.lcm_url)
    except ValueError as e:
        parser.error(str(e))
    ack_channel = args.ack_channel or args.channel + "_ACK"

    command = laserline.command_t()
    command.utime = int(time.time() * 1e6)
    command.id = random.getrandbits(62)
    command.sender = "laserline_ctl.py@%s[%d]" % (socket.gethostname(), os.getpid())
    command.name, command.value, command.token = name, value, args.token

    listen = receiver(group, port)
    send = socket.socket(socket.AF_INET, socket.SOCK_DGRAM, socket.IPPROTO_UDP)
    send.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_TTL, ttl)
    send.sendto(datagram(args.channel, command.encode(), 0), (group, port))

    deadline = time.monotonic() + args.timeout
    while True:
        left = deadline - time.monotonic()
        if left <= 0:
            print("laserline_ctl.py: no answer on %s within %g s" % (ack_channel, args.timeout),
                  file=sys.stderr)
            return 3
        listen.settimeout(left)
        try:
            data = listen.recv(MAX_DATAGRAM)
        except socket.timeout:
            continue
        if len(data) < 9 or struct.unpack_from(">I", data)[0] != SHORT_MAGIC:
            continue  # a fragment of a large message (a raw frame): never an answer
        end = data.find(b"\0", 8)
        if end < 0 or data[8:end].decode("utf-8", "replace") != ack_channel:
            continue
        try:
            ack = laserline.command_ack_t.decode(data[end + 1:])
        except (ValueError, struct.error):
            print("laserline_ctl.py: %s: a message that is not a command_ack_t; skipped"
                  % ack_channel, file=sys.stderr)
            continue
        if ack.id != command.id:
            continue  # another sender's
        if not ack.accepted:
            if ack.value:
                print("refused: %s (in force: %s)" % (ack.reason, ack.value))
            else:
                print("refused: %s" % ack.reason)
            return 1
        if name == "get":
            print(ack.value)
        else:
            print("%s = %s (was %s)" % (ack.name, ack.value, ack.old_value))
        return 0


if __name__ == "__main__":
    sys.exit(main())
