#!/usr/bin/env python3
"""A configuration session on the gateway, for the size report's stack
figure: what the firmware does when its configuration page changes.

Usage: config_session.py IAI PROTOCOL_B [HTTP]

With `iai` on the protocol-B port (HOST:PORT): the password set on the
fresh gateway together with a setting, the page read back, the setting
changed again with the password, a wrong password refused. With HTTP
(HOST:PORT, the Ethernet build): the status page, its live part, the
configuration form and the frames read, a form saved with the password and
one refused for a wrong one. Prints what each step answered; exits 1 with
`FAIL: ...` on stderr when a step does not answer as it should.
"""

import subprocess
import sys
import time
import urllib.error
import urllib.request

PASSWORD = "size-report-1"


def iai(exe, pb, *args, ok=True):
    out = subprocess.run([exe, *args, "--tcp", pb], capture_output=True, text=True, timeout=120)
    if (out.returncode == 0) != ok:
        sys.exit(f"FAIL: iai {' '.join(args)}: {out.returncode} {out.stderr.strip()}")
    print(f"iai {args[0]} {args[1]} {args[2] if len(args) > 2 else ''}: {out.returncode}")


def http(base, path, body=None):
    headers = {"Origin": base} if body is not None else {}
    if body is not None:
        headers["Content-Type"] = "application/x-www-form-urlencoded"
    req = urllib.request.Request(base + path, data=body, headers=headers)
    try:
        with urllib.request.urlopen(req, timeout=20) as r:
            status = r.status
            r.read()
    except urllib.error.HTTPError as e:
        status = e.code
    print(f"http {'POST' if body is not None else 'GET'} {path}: {status}")
    return status


def main():
    if len(sys.argv) not in (3, 4):
        sys.exit(__doc__)
    exe, pb = sys.argv[1], sys.argv[2]
    iai(exe, pb, "bridge", "config", "set", f"access.password={PASSWORD}", "modbus.poll_ms=200")
    iai(exe, pb, "bridge", "config", "get")
    iai(exe, pb, "bridge", "config", "set", "modbus.poll_ms=100", "--password", PASSWORD)
    iai(exe, pb, "bridge", "config", "set", "modbus.poll_ms=300", "--password", "wrong-pass", ok=False)
    if len(sys.argv) == 4:
        base = "http://" + sys.argv[3]
        time.sleep(1.1)
        for path in ("/", "/live", "/config", "/frames.txt"):
            if http(base, path) != 200:
                sys.exit(f"FAIL: GET {path}")
        saved = http(base, "/config", f"modbus.poll_ms=150&password={PASSWORD}".encode())
        wrong = http(base, "/config", b"modbus.poll_ms=250&password=wrong-pass")
        if (saved, wrong) != (200, 403):
            sys.exit(f"FAIL: the forms answered {saved} and {wrong}")


if __name__ == "__main__":
    main()
