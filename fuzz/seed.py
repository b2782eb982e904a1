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
# as PositionStream::ALL in core/src/position/kinds.rs.
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


def link(flags=0x02, timeout=10, turnaround=1, late=500, dup=300, seed=0x1234, base=1000, station=0x99):
    # The line of the engine targets (common/link.rs): station; timeout
    # byte (1 + 20 x b ms); flags (bits 0-1 sends 1-4, 0x04 resend unsafe,
    # 0x08 fences off, 0x10 raw noise, 0x20-0x80 the target's); turnaround
    # byte; late window; duplicate window; fence seed; start tick.
    return bytes([station, timeout, flags, turnaround]) + le(late, 2) + le(dup, 2) + le(seed, 2) + le(base, 4)


def transfer_seed(kind_index, verify_index, size, frame_room, script, shape=0, resp_room=7, line=None, b=0xFC, resumes=2):
    # the line; kind + 5 x verify policy (Full, AfterFault, Off); size;
    # table seed; shape; range start; first number; frame room (x4); reply
    # room (8-axis records); rewrites (b % 4) and max_records (1 + b / 4);
    # resumes; then the script (empty: a well-behaved controller).
    cfg = (line or link()) + bytes([kind_index + 5 * verify_index, size, 7, shape]) + le(1, 2) + le(1, 2)
    cfg += bytes([frame_room, resp_room, b, resumes])
    return cfg + bytes(script)


def readback_seed(kind_index, first, span, room, mask, script, confirm=True, line=None, resumes=1):
    # the line; kind (c % 3) | 0x10 confirmed reads; first; span; reply
    # room; table seed; mask of defined positions; resumes; then the script.
    c = kind_index | (0x10 if confirm else 0)
    cfg = (line or link()) + bytes([c]) + le(first, 2) + bytes([span, room, 5]) + le(mask, 4) + bytes([resumes])
    return cfg + bytes(script)


def client_seed(picks, script=b"", flags=0x02, requests=1, line=None):
    # the line (flags 0x20: 216H detail, 0x40: not for bridge codes);
    # requests - 1; the first request's pick, then the script (picks of
    # later requests are read when they start).
    cfg = (line or link(flags=flags)) + bytes([requests - 1])
    return cfg + bytes(picks) + bytes(script)


def line_seed(ops, flags=0x03, timeout=10, turnaround=1, late=500, dup=300, seed=0x123456, base=1000):
    # station; timeout byte; flags (sends % 5, 0x08 resend unsafe, 0x10
    # fences off, 0x20 @@); turnaround; late window; duplicate window;
    # fence seed (u32); start tick; then operations (0 start + pick, 1
    # start_raw + id + sends, 2 poll, 3 sent, 4 reply + k + digits, 5 & +
    # k + code, 6 200H + k, 7 foreign + k, 8 broken + k, 9 unread, 10
    # abandon, 11 clock + k + amount, 12 poll and send + ms).
    cfg = bytes([0x99, timeout, flags, turnaround]) + le(late, 2) + le(dup, 2) + le(seed, 4) + le(base, 4)
    return cfg + bytes(ops)


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
    # The skipper against the decoder: bad checksums, `@@`, lower-case SC,
    # a 200H whose text holds a header byte.
    skip = b"!9925B3D\r\n!9925B@@\r\n#99212A\r\n!99200!9921201391A\r\n#992322c\r\n#992322C\r\n"
    for pol in (0, 1, 2):
        write("decoder", f"skipper-policy{pol}", bytes([pol, 0x00]) + skip)
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
    # policy, then one seed per fault (op byte of the first write: bits 3-4
    # fate, 3 = swap; bits 5-7 the reply's fault, then extra and delay).
    for ki in range(5):
        for vi in range(3):
            write("transfer", f"kind{ki}-verify{vi}-clean", transfer_seed(ki, vi, 12, 40, []))
        write("transfer", f"kind{ki}-one-frame", transfer_seed(ki, 0, 3, 255, []))
    write("transfer", "swap", transfer_seed(0, 0, 6, 40, [0x01, 0x19]))
    write("transfer", "swap-reupload", transfer_seed(0, 0, 6, 40, [0x01, 0x19], shape=0x04))
    write("transfer", "lost-reply", transfer_seed(0, 1, 6, 40, [0x01, 0x21, 0x00] + list(le(0, 2))))
    write("transfer", "late-copy", transfer_seed(0, 2, 6, 40, [0x01, 0xE1, 0x20] + list(le(400, 2))))
    write("transfer", "error-reply", transfer_seed(0, 0, 6, 40, [0x01, 0xA1, 0x01] + list(le(2, 2))))
    write("transfer", "partial-write", transfer_seed(1, 0, 6, 60, [0x01, 0x81, 0x01] + list(le(2, 2))))
    write("transfer", "readback-lie", transfer_seed(0, 0, 6, 40, [0x01, 0x01, 0x81, 0x03] + list(le(2, 2))))
    write("transfer", "readback-stale", transfer_seed(0, 0, 6, 40, [0x01, 0x01, 0x01, 0xC1, 0x00] + list(le(2, 2))))
    write("transfer", "noise", transfer_seed(0, 0, 4, 40, [0x01, 0x01, 0x01, 12] + list(b"#9926D0001\r?")))
    write("transfer", "repeated-record", transfer_seed(0, 0, 9, 40, [], shape=0x06))
    write("transfer", "empty-table", transfer_seed(0, 0, 0, 40, []))
    write("transfer", "fences-off", transfer_seed(0, 0, 6, 40, [], line=link(flags=0x0A)))
    # readback: confirmed and not, a lie, a stale answer, a late copy,
    # near position 0xFFFF, an empty table.
    for ki in range(3):
        write("readback", f"kind{ki}-confirmed", readback_seed(ki, 1, 60, 1, 0x0F0F00FF, []))
        write("readback", f"kind{ki}-unconfirmed", readback_seed(ki, 1, 60, 1, 0x0F0F00FF, [], confirm=False))
    write("readback", "lie", readback_seed(0, 1, 20, 0, 0xFFFFFFFF, [0x01, 0x81, 0x00] + list(le(2, 2))))
    write("readback", "stale", readback_seed(0, 1, 20, 0, 0xFFFFFFFF, [0x01, 0x01, 0x01, 0xC1, 0x00] + list(le(2, 2))))
    write("readback", "late-copy", readback_seed(0, 1, 60, 0, 0x0F0F00FF, [0x01, 0xE1, 0x20] + list(le(400, 2))))
    write("readback", "near-top", readback_seed(0, 0xFFF8, 20, 1, 0xFFFF, []))
    write("readback", "empty", readback_seed(0, 1, 60, 0, 0, []))
    # client: each kind of request answered at once; an & with and without
    # the 216H detail (controller and bridge code); a lost reply; an unsafe
    # command timing out; a late copy; a software reset then a query.
    for pick in range(5):
        write("client", f"pick{pick}", client_seed([pick]))
    for i in (0, 10, 20, 30, 40):
        write("client", f"catalogue{i}", client_seed([5, i]))
    write("client", "error-detail", client_seed([0], [0x01, 0x81, 0x01] + list(le(2, 2)), flags=0x22))
    write("client", "bridge-code-no-detail", client_seed([0], [0x01, 0x81, 0x00] + list(le(2, 2)), flags=0x62))
    write("client", "lost-reply", client_seed([0], [0x01, 0x21, 0x00] + list(le(0, 2))))
    write("client", "unsafe-timeout", client_seed([1], [0x01, 0x21, 0x00] + list(le(0, 2))))
    write("client", "late-copy", client_seed([0, 0], [0x01, 0xE1, 0x10] + list(le(300, 2)), requests=2))
    write("client", "reset-then-query", client_seed([2, 0], [0x01, 0x01], requests=2))
    write("client", "fences-off", client_seed([0, 0], [], flags=0x0A, requests=2))
    # line: a reply, timeouts, an &, a mismatch then the reply, a command
    # without normal response, an abandon during a send, a copy waited
    # out, a clock that wraps.
    write("line", "fence-then-reply", line_seed([0, 10, 2, 3, 6, 0, 2, 11, 0, 5, 2, 3, 4, 0x02, 1, 2, 2]))
    write("line", "timeouts", line_seed([0, 10, 12, 0, 6, 0, 12, 0, 11, 2] + list(le(600, 2)) + [12, 0, 11, 2] + list(le(600, 2)) + [12, 0]))
    write("line", "error-reply", line_seed([0, 10, 12, 0, 6, 0, 12, 0, 5, 0] + list(le(0xC74, 2)) + [2]))
    write("line", "mismatch-then-reply", line_seed([0, 10, 12, 0, 6, 0, 12, 0, 4, 0x81, 0, 4, 0x00, 2]))
    write("line", "no-normal-reply", line_seed([1] + list(le(0x25B, 2)) + [1, 12, 0, 6, 0, 12, 0, 11, 2] + list(le(4000, 2)) + [2, 0, 10, 2]))
    write("line", "abandon-while-sending", line_seed([0, 10, 2, 10, 0, 10, 2]))
    write("line", "copy-waited-out", line_seed([0, 10, 12, 0, 6, 0, 12, 0, 4, 0, 0, 10, 2, 11, 1, 200, 2, 11, 2] + list(le(400, 2)) + [2]))
    write("line", "wrapping", line_seed([0, 10, 12, 0, 6, 0, 12, 0, 11, 3] + list(le(0x7FFFFFFF, 4)) + [2, 0, 10, 2], base=0xFFFFFF00))
    # bridge_policy: mode (policy, flow), [allow-list map], tick step, host bytes.
    allow = bytearray(32)
    for i in (0x12, 0x16, 0x6D):
        allow[i // 8] |= 1 << (i % 8)
    for mode in (0x00, 0x01, 0x11, 0x20):
        write("bridge_policy", f"fixtures-mode{mode:02x}", bytes([mode, 4]) + stream)
    write("bridge_policy", "fixtures-allow", bytes([0x02]) + bytes(allow) + bytes([4]) + stream)
    write("bridge_policy", "status-query", bytes([0x01, 1]) + b"!BBB0047\r\n" + stream)
    # tcp_hosts: connection events (see its header). A host and a second
    # connection refused after the hold; a host that leaves and the next
    # one served; a host that stops reading and is reset after 10 s; a
    # 26DH cut by a reset; a host that half-closes after a command.
    write("tcp_hosts", "refused", bytes([0x00, 0x02, 0x00, 0x10, 0x06, 0x14]))
    write("tcp_hosts", "next-host", bytes([0x00, 0x02, 0x01, 0x04, 0x10, 0x06, 0x14, 0x00, 0x02, 0x01]))
    write("tcp_hosts", "stops-reading",
          bytes([0x00, 0x05]) + bytes([0x02, 0x01]) * 30 + bytes([0x06, 120, 0x10, 0x12, 0x01, 0x06, 0x05]))
    write("tcp_hosts", "cut-26dh", bytes([0x00, 0x02, 0x03, 0x04, 0x06, 0x40, 0x10, 0x12, 0x01]))
    write("tcp_hosts", "half-close", bytes([0x00, 0x02, 0x00, 0x03, 0x06, 0x40, 0x10, 0x12, 0x01]))
    # config_messages (see its header): a fresh gateway's password, then a
    # whole page staged (window k = k * 8 + 1, unit byte) and applied, read
    # back, a restart; a wrong apply; the verifier read.
    windows = b"".join(bytes([0x00, w * 8 + 1, 9]) for w in range(15))
    write("config_messages", "password-stage-apply-restart",
          bytes([0x00, 0x04, 9]) + windows + bytes([0x00, 0x02, 9, 0x00, 0x00, 9, 0x00, 0x06, 9, 0x02, 3]))
    write("config_messages", "fresh-apply-refused", windows + bytes([0x00, 0x02, 9, 0x00, 0x03, 9]))
    write("config_messages", "verifier", bytes([0x00, 0x04, 9, 0x00, 0x07, 9, 0x00, 0x05, 9]))
    # http_clients (see its header): a page read; the fresh gateway's
    # password and unit through the form, then a wrong password, another
    # origin, basic authentication, a restart; a flood of silent
    # connections; a slow head.
    write("http_clients", "pages", bytes([0x00, 0x02, 0x00, 0x06, 0x05, 0x00, 0x02, 0x02, 0x06, 0x05]))
    write("http_clients", "forms",
          bytes([0x00, 0x02, 0x04, 0x06, 0x03, 0x00, 0x02, 0x06, 0x06, 0x0C, 0x00, 0x02, 0x07,
                 0x06, 0x03, 0x00, 0x02, 0x05, 0x06, 0x03, 0x00, 0x02, 0x09, 0x06, 0x03, 0x00, 0x02, 0x08]))
    write("http_clients", "flood", bytes([0x00, 0x10, 0x20, 0x06, 0x02, 0x00, 0x02, 0x00, 0x06, 0x05]))
    write("http_clients", "slow-head", bytes([0x00, 0x01, 0x08]) + b"GET / HT" + bytes([0x06, 0x40]))
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
    # sparkplug: broker behaviour (see its header). A whole session with
    # the primary host, commands, a rebirth and a reset; broken packets.
    write("sparkplug", "session", bytes([0x01, 0x00, 0x02, 0x03, 0x0A, 0x09, 0x05, 0x06, 0x00,
                                         0x06, 0x02, 0x05, 0x0A, 0x09, 0x05, 0x04, 0x08, 0x09, 0x14, 0x00]))
    write("sparkplug", "broken", bytes([0x00, 0x00, 0x02, 0x0A, 0x03, 0x06, 0x05, 0x06, 0x04,
                                        0x07, 0x05, 0x30, 0x03, 0x00, 0x01, 0x61, 0x09, 0x64]))
    write("sparkplug", "refused", bytes([0x00, 0x01, 0x05, 0x09, 0x20, 0x00, 0x02, 0x03]))
    print(f"seeded {len(frames)} fixture frames into {os.path.join(HERE, 'corpus')}")


main()
