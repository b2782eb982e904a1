#!/usr/bin/env python3
"""Writes the seed corpora of the fuzz targets from host-tests/fixtures/frames.txt
and from generated position-stream frames, replies and scripts.

Deterministic: the same fixture file always gives the same files. Run via
seed.sh; corpus/ is not committed.
"""
import os
import random
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


# --- Generated frames (position streams and their replies) -----------------

# (id, header, reserved, start_width, count_width, number_width, extended),
# as PositionStream::ALL in core/src/stream.rs.
STREAMS = [
    (0x26D, "!", False, 0, 4, 4, False),
    (0x245, "!", False, 0, 3, 3, False),
    (0x244, "!", False, 3, 3, 0, False),
    (0x290, "!", True, 4, 4, 0, True),
    (0x291, "!", True, 0, 4, 4, True),
    (0x209, "#", False, 0, 3, 3, False),
    (0x21F, "#", False, 0, 4, 4, False),
    (0x22D, "#", True, 0, 4, 4, True),
]


def hexw(v, w):
    return ("%0*X" % (w, v & ((1 << (4 * w)) - 1))).encode()


def frame(header, station, code, body):
    head = header.encode() + hexw(station, 2) + hexw(code, 3) + body
    return head + hexw(sum(head), 2) + b"\r\n"


def record(number_width, extended, number, bits, acc, dec, speed, coords, ext=0):
    out = hexw(number, number_width) if number_width else b""
    out += hexw(bits, 2) + hexw(acc, 4) + hexw(dec, 4) + hexw(speed, 4)
    out += b"".join(hexw(c, 8) for c in coords)
    if extended:
        out += hexw(ext, 2)
    return out


def stream_frame(kind, station, start, recs):
    code, header, reserved, sw, cw, nw, ext = kind
    body = (b"00" if reserved else b"") + (hexw(start, sw) if sw else b"") + hexw(len(recs), cw)
    for i, (bits, coords) in enumerate(recs):
        body += record(nw, ext, start + i + 1, bits, 30, 30, 100, coords, i)
    return frame(header, station, code, body)


def write_reply(kind, station, start, count):
    code, header, reserved, sw, cw, nw, ext = kind
    body = (b"00" if reserved else b"") + (hexw(start, sw) if sw else b"") + hexw(count, cw)
    return frame("#", station, code, body)


def sample_records(rng, n):
    out = []
    for _ in range(n):
        bits = rng.choice([0x01, 0x03, 0x0F, 0xFF, rng.randrange(256)])
        k = bin(bits).count("1")
        out.append((bits, [rng.randrange(-(1 << 31), 1 << 31) for _ in range(k)]))
    return out


def generated_frames(rng):
    """(name, frame) of valid position-stream frames of every kind and the
    normal replies to the writes."""
    out = []
    for kind in STREAMS:
        name = "gen-%03X" % kind[0]
        for n in (0, 1, 3):
            out.append((f"{name}-{n}", stream_frame(kind, 0x99, 1, sample_records(rng, n))))
        if kind[1] == "!":
            out.append((f"{name}-reply", write_reply(kind, 0x99, 1, 3)))
    return out


def le(v, n):
    return (v & ((1 << (8 * n)) - 1)).to_bytes(n, "little")


def transfer_seed(kind_index, size, frame_room, script_ops):
    # config byte: kind (c % 5) with bit 7 = station 99; size; seed; start;
    # frame room (x4); timeout byte; tries; turnaround; late guard; start
    # tick; resumes; first number.
    cfg = bytes([0x80 | kind_index, size, 7]) + le(1, 2) + bytes([frame_room, 10, 2, 0]) + le(500, 2)
    cfg += le(1000, 4) + bytes([1]) + le(1, 2)
    return cfg + bytes(script_ops)


def readback_seed(kind_index, first, span, room, asked_records):
    # config byte: kind (c % 3) with bit 7 = station 99; first; span; reply
    # room; timeout; tries; turnaround; start tick.
    cfg = bytes([0x80 | kind_index]) + le(first, 2) + bytes([span, room, 10, 2, 0]) + le(1000, 4)
    extended = kind_index == 1
    script = b""
    for n in asked_records:
        # op 2: a normal reply of n records numbered from the window start.
        script += bytes([2, n, 1])
        for i in range(n):
            script += le(0, 2) + bytes([0x03]) + le(1000 * i, 4) + le(-5 * i, 4)
            if extended:
                script += bytes([i])
            script += le(30, 2) + le(30, 2) + le(100, 2)
        script += bytes([5])  # let the turnaround pass
    return cfg + script


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

    rng = random.Random(6)  # fixed: the same seeds every run
    gen = generated_frames(rng)
    for name, frame_bytes in gen:
        write("decoder", name, bytes([0x00, 0x00]) + frame_bytes)
        write("frame_parse", name, frame_bytes)
    pos_frames = [(n, f) for n, f in frames if re.match(rb"[!#]..(26D|245|244|290|291|209|21F|22D)", f)]
    # stream_decoder mode 0: config (bit 0 = 0, policy bits 1-2), k cuts, stream.
    for name, frame_bytes in pos_frames + [g for g in gen if not g[0].endswith("reply")]:
        write("stream_decoder", name, bytes([0x00, 0x00]) + frame_bytes)
    all_pos = b"".join(f for _, f in gen if True)
    write("stream_decoder", "all-generated", bytes([0x00, 0x00]) + all_pos)
    write("stream_decoder", "all-generated-cut", bytes([0x04, 0x03, 6, 0, 30]) + all_pos)
    write("stream_decoder", "all-fixtures", bytes([0x02, 0x00]) + stream)
    # stream_decoder mode 1: station, start, n, then record bytes.
    for n in (0, 1, 5, 11):
        rec_bytes = bytes(rng.randrange(256) for _ in range(40 * n))
        write("stream_decoder", f"roundtrip-{n}", bytes([0x01, 0x02, 4, 9, 0x99]) + le(0x123, 2) + bytes([n]) + rec_bytes)
    # transfer: [transmit op 0, reply op 2 + split byte], then per frame
    # [turnaround op 5, transmit op 0, reply op 2 + split].
    confirm_all = [0x00, 0x02, 0x07] + [0x05, 0x00, 0x02, 0x07] * 40
    for ki in range(5):
        write("transfer", f"kind{ki}-confirm", transfer_seed(ki, 12, 40, confirm_all))
        write("transfer", f"kind{ki}-one-frame", transfer_seed(ki, 3, 255, confirm_all))
    write("transfer", "timeouts", transfer_seed(0, 6, 40, [0x00, 0x05, 0x00, 0x05, 0x00, 0x02, 0x07] + confirm_all[3:]))
    write("transfer", "error-replies", transfer_seed(0, 6, 40, [0x00, 0x04, 0x21, 0x00, 0x00, 0x02, 0x07] + confirm_all[3:]))
    write("transfer", "noise", transfer_seed(0, 4, 40, [0x00, 0x01, 12] + list(b"#9926D0001\r\n") + confirm_all[1:]))
    write("transfer", "empty-table", transfer_seed(0, 0, 40, []))
    # readback: one reply per window.
    for ki in range(3):
        write("readback", f"kind{ki}-one-window", readback_seed(ki, 1, 5, 7, [3]))
        write("readback", f"kind{ki}-three-windows", readback_seed(ki, 1, 20, 0, [1, 0, 1] + [1] * 20))
    write("readback", "near-top", readback_seed(0, 0xFFF8, 20, 1, [2, 2, 2, 2, 2]))
    # bridge_policy: mode (policy, flow), [allow-list map], tick step, host bytes.
    allow = bytearray(32)
    for i in (0x12, 0x16, 0x6D):
        allow[i // 8] |= 1 << (i % 8)
    for mode in (0x00, 0x01, 0x11, 0x20):
        write("bridge_policy", f"fixtures-mode{mode:02x}", bytes([mode, 4]) + stream)
    write("bridge_policy", "fixtures-allow", bytes([0x02]) + bytes(allow) + bytes([4]) + stream)
    write("bridge_policy", "status-query", bytes([0x01, 1]) + b"!BBB0047\r\n" + stream)
    # hex: any bytes; the fixture frames hold digits of both cases and
    # every kind of non-digit next to them.
    for name, frame in frames[:8]:
        write("hex", name, frame)
    write("hex", "digits-both-cases", b"0123456789ABCDEFabcdef@G`g/:\x00\xff")
    print(f"seeded {len(gen)} generated frames, {len(pos_frames)} fixture position frames")
    print(f"seeded {len(frames)} fixture frames into {os.path.join(HERE, 'corpus')}")


main()
