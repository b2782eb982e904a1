#!/usr/bin/env python3
"""Protocol-B reply latency on the Ethernet gateway with and without the
web page busy: the bridge's status query (B00H, answered by the bridge
itself) and a 212H through it to the controller, asked one after the
other on one connection, first alone, then while web clients fetch the
status page (and its live part) as fast as they can. The status page is
read once first in both cases, so that the Modbus gateway polls the
controller in both (a page looked at starts the polling, as a PLC does):
what differs is the web page's own work.

Usage: latency.py PROTOCOL_B HTTP [QUERIES] [WEB_CLIENTS]

PROTOCOL_B and HTTP are what `./tools/gateway.sh --ethernet` prints
(`127.0.0.1:PORT`). Prints, for each case and each message, the median,
the 99th percentile and the worst round trip in ms, and how many pages
the web clients fetched meanwhile. Under QEMU the figures are the
emulator's and this machine's, not a Cortex-M3's: they show whether the
web page holds the bridge back, not how long an LM3S6965 takes.
"""

import socket
import sys
import threading
import time
import urllib.request


def frame(station, code, body=b""):
    data = b"!" + b"%02X" % station + b"%03X" % code + body
    sc = sum(data) & 0xFF
    return data + b"%02X" % sc + b"\r\n"


def round_trips(pb, n):
    host, port = pb.rsplit(":", 1)
    s = socket.create_connection((host, int(port)), timeout=10)
    s.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    out = {"B00 (the bridge)": [], "212 (the controller)": []}
    for i in range(n):
        for name, f in (
            ("B00 (the bridge)", frame(0xBB, 0xB00)),
            ("212 (the controller)", frame(0x99, 0x212, b"01")),
        ):
            t0 = time.perf_counter()
            s.sendall(f)
            buf = b""
            while not buf.endswith(b"\r\n"):
                chunk = s.recv(4096)
                if not chunk:
                    raise SystemExit("FAIL: the gateway closed the connection")
                buf += chunk
            out[name].append((time.perf_counter() - t0) * 1000)
    s.close()
    return out


def hammer(http, stop, count):
    while not stop.is_set():
        for path in ("/", "/live", "/config"):
            try:
                with urllib.request.urlopen(f"http://{http}{path}", timeout=10) as r:
                    r.read()
                    count[0] += 1
            except Exception:
                time.sleep(0.05)


def show(case, rtts, pages=None):
    for name, v in rtts.items():
        v = sorted(v)
        p99 = v[min(len(v) - 1, int(len(v) * 0.99))]
        print(
            f"{case}: {name}: median {v[len(v) // 2]:.1f} ms, 99% {p99:.1f} ms, "
            f"worst {v[-1]:.1f} ms over {len(v)}"
            + (f"; {pages} pages fetched meanwhile" if pages is not None else "")
        )


def main():
    if len(sys.argv) < 3:
        sys.exit(__doc__)
    pb, http = sys.argv[1], sys.argv[2]
    n = int(sys.argv[3]) if len(sys.argv) > 3 else 200
    clients = int(sys.argv[4]) if len(sys.argv) > 4 else 2
    with urllib.request.urlopen(f"http://{http}/live", timeout=10) as r:
        r.read()
    time.sleep(1.0)
    show("web idle", round_trips(pb, n))
    stop = threading.Event()
    count = [0]
    threads = [threading.Thread(target=hammer, args=(http, stop, count)) for _ in range(clients)]
    for t in threads:
        t.start()
    time.sleep(1.0)
    try:
        rtts = round_trips(pb, n)
    finally:
        stop.set()
        for t in threads:
            t.join()
    show(f"{clients} web clients fetching pages", rtts, count[0])


if __name__ == "__main__":
    main()
