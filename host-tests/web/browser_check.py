#!/usr/bin/env python3
"""The gateway's web page in a real browser (headless Chromium through
Selenium), as a plant's technician uses it.

Usage: browser_check.py --http URL --protocol-b HOST:PORT --modbus HOST:PORT
                        --iai PATH --out DIR

URL is what `./tools/gateway.sh --ethernet` prints as `http 127.0.0.1:PORT`
(a fresh gateway: no password yet). In order:

1. axis 1 is moved with `iai send` (servo on, home, a move to 12.345 mm);
   the status page, refreshed by its own script, shows axis 1 at the
   position `iai send 212` reads from the controller, and the same page
   with JavaScript off shows it too;
2. the configuration form on a fresh gateway asks for a password; saved
   with one and Modbus unit 7, it says so;
3. a wrong password changes nothing (403, and the form still shows 7);
   a form from another origin (a page of its own, `Origin: null`) is
   refused (403) and changes nothing;
4. the last frames download as text;
5. the restart button with the password: the gateway restarts, and a
   Modbus TCP client then gets answers on unit 7 and none on unit 1.

Screenshots of each page go to DIR. Prints `ok STEP ...` lines on stdout;
exits 1 with `FAIL: ...` on stderr at the first thing that is not as it
should be. Chromium runs headless without a sandbox, its background
networking off (the machine's network is closed) and a fresh profile in
DIR.
"""

import argparse
import json
import os
import subprocess
import sys
import time
import urllib.error
import urllib.request

from pymodbus.client import ModbusTcpClient
from selenium import webdriver
from selenium.webdriver.chrome.service import Service
from selenium.webdriver.common.by import By

PASSWORD = "plant-1234"
WAIT_S = 30.0


class Fail(Exception):
    pass


def ok(step, detail=""):
    print(f"ok {step} {detail}".rstrip(), flush=True)


def browser(out, name, javascript=True):
    """Headless Chromium with a fresh profile, downloads into OUT."""
    opts = webdriver.ChromeOptions()
    opts.binary_location = "/usr/bin/chromium"
    for flag in (
        "--headless=new",
        "--no-sandbox",
        "--disable-gpu",
        "--disable-background-networking",
        "--disable-component-update",
        "--disable-sync",
        "--no-first-run",
        "--window-size=1200,1600",
        f"--user-data-dir={os.path.join(out, 'profile-' + name)}",
    ):
        opts.add_argument(flag)
    prefs = {
        "download.default_directory": out,
        "download.prompt_for_download": False,
    }
    if not javascript:
        prefs["profile.managed_default_content_settings.javascript"] = 2
    opts.add_experimental_option("prefs", prefs)
    # The driver is Debian's: Selenium Manager must not look for one.
    os.environ["SE_OFFLINE"] = "true"
    d = webdriver.Chrome(service=Service("/usr/bin/chromedriver"), options=opts)
    d.set_page_load_timeout(WAIT_S)
    return d


def shot(d, out, name):
    path = os.path.join(out, f"{name}.png")
    d.save_screenshot(path)
    return path


def iai(args, exe, pb):
    out = subprocess.run(
        [exe, *args, "--tcp", pb], capture_output=True, text=True, timeout=60
    )
    if out.returncode != 0:
        raise Fail(f"iai {' '.join(args)}: {out.stderr.strip()}")
    return out.stdout


def position_212(exe, pb):
    """Axis 1's current position (0.001 mm) as `iai send 212` reads it."""
    reply = json.loads(iai(["send", "212", "query_axis_pattern=1", "--json"], exe, pb))
    return reply["fields"]["axes"][0]["current_position"]


def wait_for(what, check, limit=WAIT_S):
    end = time.monotonic() + limit
    last = None
    while time.monotonic() < end:
        try:
            got = check()
            if got:
                return got
        except Exception as e:  # the page between two refreshes
            last = e
        time.sleep(0.3)
    raise Fail(f"{what} within {limit:.0f} s{f' ({last})' if last else ''}")


def page_mm(d):
    return d.find_element(By.ID, "pos1").text.strip()


def mm_of(thousandths):
    sign = "-" if thousandths < 0 else ""
    a = abs(thousandths)
    return f"{sign}{a // 1000}.{a % 1000:03d}"


def modbus_answers(host, port, unit):
    c = ModbusTcpClient(host, port=port, timeout=1.0, retries=0)
    if not c.connect():
        raise Fail(f"cannot connect to Modbus TCP {host}:{port}")
    try:
        r = c.read_input_registers(0x9000, count=2, device_id=unit)
        return not r.isError()
    except Exception:
        return False
    finally:
        c.close()


def http_status(url, data=None, headers=None):
    req = urllib.request.Request(url, data=data, headers=headers or {})
    try:
        with urllib.request.urlopen(req, timeout=10) as r:
            return r.status, r.read().decode()
    except urllib.error.HTTPError as e:
        return e.code, e.read().decode()


def fill(d, key, value):
    el = d.find_element(By.ID, key)
    if el.tag_name == "select":
        el.find_element(By.XPATH, f"option[. = '{value}']").click()
    else:
        el.clear()
        el.send_keys(value)


def run(a):
    base = a.http.rstrip("/")
    if not base.startswith("http"):
        base = "http://" + base
    mb_host, mb_port = a.modbus.rsplit(":", 1)
    os.makedirs(a.out, exist_ok=True)

    # 1. Axis 1 moved; the page shows what 212H reads.
    iai(["send", "232", "axis_pattern=1", "operation_type=on"], a.iai, a.protocol_b)
    iai(["send", "233", "axis_pattern=1"], a.iai, a.protocol_b)
    time.sleep(1.0)
    iai(["send", "234", "speed=200", "absolute_coordinate=12345"], a.iai, a.protocol_b)
    d = browser(a.out, "main")
    try:
        d.get(base + "/")
        want = wait_for(
            "axis 1 at rest at 12.345 mm (212H)",
            lambda: (p := position_212(a.iai, a.protocol_b)) == 12345 and p,
        )
        # The page refreshes its live part every 2 s by itself.
        shown = wait_for(
            "the status page showing axis 1 at 212H's position",
            lambda: page_mm(d) == mm_of(want) and page_mm(d),
        )
        again = position_212(a.iai, a.protocol_b)
        if again != want:
            raise Fail(f"212H says {again}, then {want}")
        # Refreshed live: the uptime moves on without a reload.
        up = d.find_element(By.ID, "uptime").text
        wait_for(
            "the uptime refreshed by the page's script",
            lambda: d.find_element(By.ID, "uptime").text != up,
            limit=10,
        )
        shot(d, a.out, "status")
        ok("status", f"axis 1 at {shown} mm on the page, {want} (0.001 mm) by iai send 212")

        nojs = browser(a.out, "nojs", javascript=False)
        try:
            nojs.get(base + "/")
            if page_mm(nojs) != mm_of(want):
                raise Fail(f"without JavaScript the page shows {page_mm(nojs)}")
            shot(nojs, a.out, "status-without-javascript")
        finally:
            nojs.quit()
        ok("no-javascript", "the status page reads without JavaScript")

        # 2. A fresh gateway asks for a password; saved with one.
        d.get(base + "/config")
        if not d.find_elements(By.ID, "no-password"):
            raise Fail("the fresh gateway's form does not ask for a password")
        if d.find_elements(By.ID, "password"):
            raise Fail("a fresh gateway's form asks for a current password")
        shot(d, a.out, "config-fresh")
        fill(d, "modbus.unit", "7")
        fill(d, "new_password", PASSWORD)
        fill(d, "new_password2", PASSWORD)
        d.find_element(By.ID, "save").click()
        result = d.find_element(By.ID, "result").text
        if not result.startswith("Saved as sequence"):
            raise Fail(f"saving said {result!r}")
        shot(d, a.out, "config-saved")
        ok("save", f"{result}, Modbus unit 7 and a password")

        # 3. A wrong password changes nothing; nor does another origin.
        d.get(base + "/config")
        fill(d, "modbus.unit", "9")
        fill(d, "password", "not-the-password")
        d.find_element(By.ID, "save").click()
        reason = d.find_element(By.ID, "reason").text
        if "wrong password" not in reason or "403" not in d.title:
            raise Fail(f"a wrong password gave {d.title!r}: {reason!r}")
        shot(d, a.out, "wrong-password")
        time.sleep(1.2)
        d.get(base + "/config")
        unit = d.find_element(By.ID, "modbus.unit").get_attribute("value")
        if unit != "7":
            raise Fail(f"after a wrong password the unit is {unit}")
        ok("wrong-password", "403 and the unit still 7")

        other = (
            "data:text/html,<form id=f method=post action='" + base + "/config'>"
            "<input name='modbus.unit' value='11'><input name=password value='"
            + PASSWORD + "'></form><script>document.getElementById('f').submit()</script>"
        )
        d.get(other)
        wait_for("the cross-origin form's answer", lambda: d.find_elements(By.ID, "reason"))
        reason = d.find_element(By.ID, "reason").text
        if "another page" not in reason:
            raise Fail(f"a form from another origin gave {reason!r}")
        shot(d, a.out, "cross-origin")
        d.get(base + "/config")
        unit = d.find_element(By.ID, "modbus.unit").get_attribute("value")
        if unit != "7":
            raise Fail(f"after a form from another origin the unit is {unit}")
        shot(d, a.out, "config")
        ok("cross-origin", "403 and the unit still 7")

        # 4. The last frames, downloaded.
        d.get(base + "/")
        d.find_element(By.ID, "frames").click()
        path = os.path.join(a.out, "frames.txt")
        text = wait_for(
            "frames.txt downloaded",
            lambda: os.path.exists(path) and open(path).read(),
        )
        if "> !99212" not in text or "< #99212" not in text:
            raise Fail(f"frames.txt lacks the 212H exchange:\n{text}")
        ok("frames", f"{len(text.splitlines())} lines")

        # 5. Restart with the password; Modbus answers on unit 7 only.
        if not modbus_answers(mb_host, int(mb_port), 1):
            raise Fail("before the restart, unit 1 does not answer")
        d.get(base + "/")
        fill(d, "restart-password", PASSWORD)
        d.find_element(By.ID, "restart").click()
        result = d.find_element(By.ID, "result").text
        if "restarts" not in result:
            raise Fail(f"restarting said {result!r}")
        shot(d, a.out, "restarting")
        time.sleep(1.0)
        wait_for(
            "the page after the restart",
            lambda: http_status(base + "/live")[0] == 200,
        )
        wait_for("Modbus answers on unit 7", lambda: modbus_answers(mb_host, int(mb_port), 7))
        if modbus_answers(mb_host, int(mb_port), 1):
            raise Fail("after the restart, unit 1 still answers")
        d.get(base + "/")
        shot(d, a.out, "status-after-restart")
        ok("restart", "Modbus TCP answers on unit 7, not on unit 1")
    finally:
        d.quit()


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--http", required=True)
    p.add_argument("--protocol-b", required=True)
    p.add_argument("--modbus", required=True)
    p.add_argument("--iai", required=True)
    p.add_argument("--out", required=True)
    a = p.parse_args()
    try:
        run(a)
    except Fail as e:
        print(f"FAIL: {e}", file=sys.stderr)
        sys.exit(1)


if __name__ == "__main__":
    main()
