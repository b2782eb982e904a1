#!/usr/bin/env python3
"""A PLC's session with the gateway's Modbus RTU port, through pymodbus.

Usage: pymodbus_plc.py [--tcp] HOST PORT [TABLE]

RTU frames over the TCP port that ./tools/gateway.sh prints as
`modbus-rtu 127.0.0.1:PORT` (pymodbus's RTU framer on a TCP client); with
--tcp, Modbus TCP (MBAP framing) to the port that
`./tools/gateway.sh --ethernet` prints as `modbus-tcp 127.0.0.1:PORT`.
The sequence a PLC runs: servo on (DRG1 SON), home (DRG1 HOME), wait for
HEND, a numeric move (9900H), wait for PEND, read PNOW; then the position
table: TABLE has one record a line, its 21 window registers in decimal;
they are written five at a time (2200H), each write waited for through the
handshake (CMDST), then read back through the window (21F0H, 2200H) and
compared. Without TABLE the session ends after PNOW.

Prints `pnow VALUE` and `table N written, read back equal`, and timings
(`time ...`), on stdout; exits 1 with `FAIL: ...` on stderr on the first
thing that is not as it should be.

A reply lost on the way is what a PLC handles: a read is asked again; a
write whose reply was lost is asked again only if CMDST's sequence number
says the gateway did not take it (the handshake's low byte counts the
commands accepted).
"""

import sys
import time

from pymodbus import FramerType
from pymodbus.client import ModbusTcpClient
from pymodbus.exceptions import ModbusException
from pymodbus.pdu import ExceptionResponse

UNIT = 1
DRG1, PNOW, DSS1, MOVN = 0x0D00, 0x9000, 0x9005, 0x9900
PWHEAD, PWREC, CMDST = 0x21F0, 0x2200, 0xB100
SON, HOME = 0x1000, 0x1010
ERROR, BUSY, DONE = 1 << 15, 1 << 14, 1 << 13
SV, HEND, PEND = 1 << 12, 1 << 4, 1 << 3
RECORD_WORDS, WINDOW = 21, 5
ATTEMPTS = 5
WAIT_S = 30.0


class Fail(Exception):
    pass


class Lost(Exception):
    pass


class Plc:
    def __init__(self, host, port, framer):
        self.client = ModbusTcpClient(
            host, port=port, framer=framer, timeout=1.0, retries=0
        )
        if not self.client.connect():
            raise Fail(f"cannot connect to {host}:{port}")
        self.lost = 0
        self.requests = 0

    def _ask(self, call, *args, **kw):
        self.requests += 1
        try:
            r = call(*args, device_id=UNIT, **kw)
        except ModbusException as e:
            raise Lost(str(e)) from e
        if isinstance(r, ExceptionResponse):
            raise Fail(f"exception {r.exception_code:02X} to {call.__name__}{args}")
        if r.isError():
            raise Lost(str(r))
        return r

    def read(self, addr, count, inputs=False):
        call = (
            self.client.read_input_registers
            if inputs
            else self.client.read_holding_registers
        )
        for _ in range(ATTEMPTS):
            try:
                return self._ask(call, addr, count=count).registers
            except Lost:
                self.lost += 1
        raise Fail(f"no answer to a read of {addr:04X} in {ATTEMPTS} attempts")

    def command(self, addr, values):
        """Writes a command and waits for the handshake: (status, code, s)."""
        seq = self.read(CMDST, 1, inputs=True)[0] & 0xFF
        t0 = time.monotonic()
        for _ in range(ATTEMPTS):
            try:
                if len(values) == 1:
                    self._ask(self.client.write_register, addr, values[0])
                else:
                    self._ask(self.client.write_registers, addr, values)
                break
            except Lost:
                self.lost += 1
                if self.read(CMDST, 1, inputs=True)[0] & 0xFF != seq:
                    break
        else:
            raise Fail(f"no answer to a write of {addr:04X} in {ATTEMPTS} attempts")
        while True:
            st, code, _ = self.read(CMDST, 3, inputs=True)
            if st & 0xFF == seq:
                raise Fail(f"the write at {addr:04X} started no command")
            if st & BUSY == 0:
                return st, code, time.monotonic() - t0
            if time.monotonic() - t0 > WAIT_S:
                raise Fail(f"command at {addr:04X} still busy after {WAIT_S} s")

    def done(self, what, addr, values):
        st, code, s = self.command(addr, values)
        if st & (DONE | ERROR) != DONE:
            raise Fail(f"{what}: status {st:04X}, code {code:03X}")
        return s

    def wait_dss1(self, bits):
        t0 = time.monotonic()
        while self.read(DSS1, 1, inputs=True)[0] & bits != bits:
            if time.monotonic() - t0 > WAIT_S:
                raise Fail(f"DSS1 never had {bits:04X}")
        return time.monotonic() - t0


def load(path):
    with open(path) as f:
        rows = [[int(v) for v in line.split()] for line in f if line.strip()]
    for r in rows:
        if len(r) != RECORD_WORDS:
            raise Fail(f"{path}: a record of {len(r)} registers")
    return rows


def ms(s):
    return f"{s * 1000:.0f} ms"


def main(host, port, table=None, framer=FramerType.RTU):
    rows = load(table) if table is not None else None
    plc = Plc(host, int(port), framer)
    t0 = time.monotonic()
    for _ in range(20):
        plc.read(PNOW, 6, inputs=True)
    print(f"time cached read (PNOW..DSS1): {ms((time.monotonic() - t0) / 20)} a request")

    print(f"time servo on: {ms(plc.done('servo on', DRG1, [SON]))}")
    plc.wait_dss1(SV)
    print(f"time home: {ms(plc.done('home', DRG1, [HOME]))}")
    print(f"time home end (HEND) after it: {ms(plc.wait_dss1(HEND))}")
    target = 25_500
    move = [(target >> 16) & 0xFFFF, target & 0xFFFF, 0, 0, 0, 200, 30, 0, 0]
    print(f"time numeric move: {ms(plc.done('numeric move', MOVN, move))}")
    print(f"time position end (PEND) after it: {ms(plc.wait_dss1(PEND))}")
    hi, lo = plc.read(PNOW, 2, inputs=True)
    pnow = (hi << 16 | lo) - ((hi & 0x8000) << 17)
    if pnow != target:
        raise Fail(f"PNOW {pnow}, not {target}")
    print(f"pnow {pnow}")
    if rows is None:
        print(f"requests {plc.requests}, replies lost {plc.lost}")
        plc.client.close()
        return

    t0 = time.monotonic()
    for i in range(0, len(rows), WINDOW):
        chunk = rows[i : i + WINDOW]
        plc.done(f"window write at {chunk[0][0]}", PWREC, [w for r in chunk for w in r])
    written = time.monotonic() - t0
    t0 = time.monotonic()
    for i in range(0, len(rows), WINDOW):
        chunk = rows[i : i + WINDOW]
        plc.done(f"window read at {chunk[0][0]}", PWHEAD, [chunk[0][0]])
        back = plc.read(PWREC, RECORD_WORDS * len(chunk))
        for k, r in enumerate(chunk):
            got = back[k * RECORD_WORDS : (k + 1) * RECORD_WORDS]
            if got != r:
                raise Fail(f"position {r[0]} read back {got}, written {r}")
    read = time.monotonic() - t0
    print(f"time table write ({len(rows)} positions): {written:.1f} s")
    print(f"time table read back: {read:.1f} s")
    print(f"table {len(rows)} written, read back equal")
    print(f"requests {plc.requests}, replies lost {plc.lost}")
    plc.client.close()


if __name__ == "__main__":
    args = sys.argv[1:]
    framer = FramerType.RTU
    if args[:1] == ["--tcp"]:
        framer = FramerType.SOCKET
        args = args[1:]
    if len(args) not in (2, 3):
        print(__doc__.splitlines()[2], file=sys.stderr)
        sys.exit(2)
    try:
        main(*args, framer=framer)
    except Fail as e:
        print(f"FAIL: {e}", file=sys.stderr)
        sys.exit(1)
