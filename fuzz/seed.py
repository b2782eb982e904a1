#!/usr/bin/env python3
"""Writes the seed corpora of the fuzz targets from host-tests/fixtures/frames.txt.

Deterministic: the same fixture file always gives the same files. Run via
seed.sh; corpus/ is not committed.
"""
import os
import re
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
FIXTURES = os.path.join(HERE, "..", "host-tests", "fixtures", "frames.txt")


def unescape(s):
    out = bytearray()
    i = 0
    while i < len(s):
        c = s[i]
        if c != "\\":
            out += c.encode("latin1")
            i += 1
            continue
        n = s[i + 1]
        if n == "r":
            out += b"\r"
        elif n == "n":
            out += b"\n"
        elif n == "\\":
            out += b"\\"
        elif n == "x":
            out.append(int(s[i + 2 : i + 4], 16))
            i += 2
        else:
            sys.exit(f"unknown escape \\{n}")
        i += 2
    return bytes(out)


def fixtures():
    name = None
    with open(FIXTURES, encoding="utf-8") as f:
        for line in f:
            if line.startswith("=="):
                name = line[2:].strip()
            elif line.startswith("frame:") and name:
                yield name, unescape(line.split(":", 1)[1].strip())


def write(target, name, data):
    d = os.path.join(HERE, "corpus", target)
    os.makedirs(d, exist_ok=True)
    with open(os.path.join(d, name), "wb") as f:
        f.write(data)


def main():
    frames = list(fixtures())
    stream = b"".join(f for _, f in frames)
    for name, frame in frames:
        # decoder: config byte (policy, capacity), no cuts, the frame.
        write("decoder", name, bytes([0x00, 0x00]) + frame)
        write("frame_parse", name, frame)
        if re.match(rb"[!#]..26D", frame) and len(frame) > 14:
            body = frame[10:-4] if frame[0:1] == b"!" else b""
            if body:
                write("position_record", name + "-read", bytes([0x04, 0x00]) + body)
                write("position_record", name + "-read3", bytes([0x03, 0x00]) + body[1:])
                write("position_record", name + "-range-ext", bytes([0x80, 0x00]) + body[4:] + b"00")
    write("decoder", "all-frames", bytes([0x00, 0x00]) + stream)
    write("decoder", "all-frames-reject-cut", bytes([0x01, 0x03, 4, 0, 17]) + stream)
    write("decoder", "all-frames-accept-small", bytes([0x06, 0x02, 9, 1]) + stream)
    write("decoder", "noise-between", bytes([0x08, 0x00]) + b"\x00xx\r\n".join(f for _, f in frames))
    # position_record round trips: layout, mode 1, then number, axes, acc,
    # dec, speed, ext, extra, coordinates (little-endian i32).
    write("position_record", "roundtrip-2-axes", bytes([0x04, 0x01, 1, 0, 0x03, 30, 0, 30, 0, 100, 0, 0, 2]) + (100000).to_bytes(4, "little", signed=True) + (-25500).to_bytes(4, "little", signed=True))
    write("position_record", "roundtrip-8-axes-ext", bytes([0x84, 0x01, 0x1F, 0x4E, 0xFF, 1, 0, 2, 0, 3, 0, 7, 2]) + b"".join((-i * 1000).to_bytes(4, "little", signed=True) for i in range(1, 9)))
    print(f"seeded {len(frames)} fixture frames into {os.path.join(HERE, 'corpus')}")


main()
