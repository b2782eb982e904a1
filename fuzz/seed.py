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


def transfer_seed(kind_index, verify_index, size, frame_room, script, shape=0, resp_room=7):
    # kind + 5 x verify policy (Full, AfterFault, Off); station; size; table
    # seed; shape; range start; first number; frame room (x4); reply room
    # (8-axis records); timeout byte (x20 ms); sends and rewrites;
    # turnaround; late window; duplicate window; start tick; resumes; then
    # the script (empty: a well-behaved controller).
    cfg = bytes([kind_index + 5 * verify_index, 0x99, size, 7, shape]) + le(1, 2) + le(1, 2)
    cfg += bytes([frame_room, resp_room, 10, 0x06, 0]) + le(500, 2) + le(300, 2)
    cfg += le(1000, 4) + bytes([2])
    return cfg + bytes(script)


def readback_seed(kind_index, first, span, room, asked_records):
    # mode 0 (arbitrary replies): kind (c % 3) with bit 7 = station 99;
    # first; span; reply room; timeout; sends; turnaround; late window;
    # duplicate window; start tick; resumes; then ops.
    cfg = bytes([0x80 | kind_index]) + le(first, 2) + bytes([span, room, 10, 2, 0])
    cfg += le(500, 2) + le(300, 2) + le(1000, 4) + bytes([1])
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


def readback_table_seed(kind_index, first, span, room, mask, script):
    # mode 1 (a controller with a table): bit 6 of the first byte; the
    # table's seed and the mask of defined positions follow the config.
    cfg = bytes([0xC0 | kind_index]) + le(first, 2) + bytes([span, room, 10, 3, 0])
    cfg += le(500, 2) + le(300, 2) + le(1000, 4) + bytes([1]) + bytes([5]) + le(mask, 4)
    return cfg + bytes(script)


def client_seed(flags, picks, script=b"", timeout=10):
    # station; timeout byte; sends (0-4) | resend unsafe 0x08 | 216H
    # detail 0x10 | requests - 1 in bits 5-6; turnaround; late window;
    # duplicate window; start tick; the first request's pick, then the
    # script (picks of later requests are read when they start).
    cfg = bytes([0x99, timeout, flags, 0]) + le(500, 2) + le(300, 2) + le(1000, 4)
    return cfg + bytes(picks) + bytes(script)


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
    # transfer: well-behaved controllers (empty script) for every kind and
    # policy, then faults: an SC-preserving swap, a lost reply, a late
    # duplicate, an & reply, a partial write, read-back lies, noise.
    for ki in range(5):
        for vi in range(3):
            write("transfer", f"kind{ki}-verify{vi}-clean", transfer_seed(ki, vi, 12, 40, []))
        write("transfer", f"kind{ki}-one-frame", transfer_seed(ki, 0, 3, 255, []))
    write("transfer", "swap", transfer_seed(0, 0, 6, 40, [0x19]))
    write("transfer", "swap-reupload", transfer_seed(0, 0, 6, 40, [0x19], shape=0x04))
    write("transfer", "lost-reply", transfer_seed(0, 1, 6, 40, [0x21, 0x00] + list(le(0, 2))))
    write("transfer", "late-duplicate", transfer_seed(0, 2, 6, 40, [0x61, 0x20] + list(le(4000, 2))))
    write("transfer", "error-reply", transfer_seed(0, 0, 6, 40, [0xA1, 0x01] + list(le(2, 2))))
    write("transfer", "partial-write", transfer_seed(1, 0, 6, 60, [0xC1, 0x01] + list(le(2, 2))))
    write("transfer", "readback-wrong", transfer_seed(0, 0, 6, 40, [0x01, 0x81, 0x10] + list(le(2, 2))))
    write("transfer", "readback-stale", transfer_seed(0, 0, 6, 40, [0x01, 0x81, 0x40] + list(le(2, 2))))
    write("transfer", "noise", transfer_seed(0, 0, 4, 40, [0x01, 0x01, 12] + list(b"#9926D0001\r?")))
    write("transfer", "repeated-record", transfer_seed(0, 0, 9, 40, [], shape=0x06))
    write("transfer", "empty-table", transfer_seed(0, 0, 0, 40, []))
    # readback: one reply per window (mode 0), and a controller's table
    # (mode 1), clean and with a late duplicate.
    for ki in range(3):
        write("readback", f"kind{ki}-one-window", readback_seed(ki, 1, 5, 7, [3]))
        write("readback", f"kind{ki}-three-windows", readback_seed(ki, 1, 20, 0, [1, 0, 1] + [1] * 20))
        write("readback", f"kind{ki}-table", readback_table_seed(ki, 1, 60, 1, 0x0F0F00FF, []))
    write("readback", "near-top", readback_seed(0, 0xFFF8, 20, 1, [2, 2, 2, 2, 2]))
    write("readback", "table-duplicate", readback_table_seed(0, 1, 60, 0, 0x0F0F00FF, [0x61, 0x20] + list(le(100, 2))))
    write("readback", "table-empty", readback_table_seed(0, 1, 60, 0, 0, []))
    # client: each kind of request, answered at once; an & with the 216H
    # detail; a lost reply (resend); 25BH; several requests in a row.
    for pick in range(5):
        write("client", f"pick{pick}", client_seed(0x03, [pick]))
    for i in (0, 10, 20, 30, 40):
        write("client", f"catalogue{i}", client_seed(0x03, [5, i]))
    write("client", "error-detail", client_seed(0x13, [0], [0x19, 0x01]))
    write("client", "bridge-code", client_seed(0x13, [0], [0x19, 0x00]))
    write("client", "lost-reply", client_seed(0x03, [0], [0x11, 0x00]))
    write("client", "unsafe-timeout", client_seed(0x03, [1], [0x11, 0x00]))
    write("client", "late-duplicate", client_seed(0x63, [0], [0xC1, 0x10] + list(le(2500, 2)) + [0, 0]))
    write("client", "reset-then-query", client_seed(0x23, [2], [0x01, 0x00]))
    # exchange: station, timeout byte, sends | resend unsafe 0x08 |
    # ByContent 0x10, turnaround, late window, duplicate window, start tick,
    # then operations (0 start + pick, 1 poll, 2 advance + u16, 3 sent,
    # 4 offer + kind byte, 6 lost/broken, 7 abandon, 8 settings).
    def exchange_seed(flags, ops):
        return bytes([0x99, 10, flags, 0]) + le(500, 2) + le(300, 2) + le(1000, 4) + bytes(ops)
    write("exchange", "reply", exchange_seed(0x03, [0, 10, 1, 3, 4, 0x00, 1]))
    write("exchange", "timeouts", exchange_seed(0x03, [0, 10, 1, 3]))
    write("exchange", "error-reply", exchange_seed(0x03, [0, 10, 1, 3, 4, 0x02] + list(le(0xC74, 2)) + [1]))
    write("exchange", "mismatch-then-reply", exchange_seed(0x03, [0, 10, 1, 3, 4, 0x10, 4, 0x00, 1]))
    write("exchange", "no-normal-reply", exchange_seed(0x03, [0, 0x82] + list(le(10000, 2)) + [1, 3]))
    write("exchange", "abandon-while-sending", exchange_seed(0x03, [0, 10, 1, 7, 0, 10, 1]))
    write("exchange", "by-content", exchange_seed(0x13, [0, 10, 1, 3, 6, 0x00, 1, 1, 3, 4, 0x00, 0, 10, 1]))
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
    # Reproducers of the findings (fuzz/README.md): always in the corpora,
    # so every run replays them.
    reg = os.path.join(HERE, "regressions")
    for target in sorted(os.listdir(reg)) if os.path.isdir(reg) else []:
        for name in sorted(os.listdir(os.path.join(reg, target))):
            with open(os.path.join(reg, target, name), "rb") as f:
                write(target, "regression-" + name, f.read())
    print(f"seeded {len(gen)} generated frames, {len(pos_frames)} fixture position frames")
    print(f"seeded {len(frames)} fixture frames into {os.path.join(HERE, 'corpus')}")


main()
