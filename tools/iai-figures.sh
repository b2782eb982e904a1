#!/usr/bin/env bash
# Figures of the iai tool (printed, not asserted): `inspect` on a 200 MB
# text log and raw capture (time, peak RSS), and `table write` of 20,000
# records of 8 axes to the simulator (wall time against the wire-limited
# minimum at 115,200 baud). Needs python3 and GNU time (/usr/bin/time).
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build -q --release -p iai-cli
iai=${CARGO_TARGET_DIR:-target}/release/iai
dir=$(mktemp -d)
trap 'kill "${sim:-}" 2>/dev/null || true; rm -rf "$dir"' EXIT

python3 - "$dir" <<'PY'
import random, sys
d = sys.argv[1]
def sc(b): return b"%02X" % (sum(b) & 0xFF)
def fr(b): return b + sc(b) + b"\\r\\n"
rec = b"".join(b"%04X03001E001E0064000186A0FFFF9C64" % (i + 1) for i in range(24))
lines = [b"> " + fr(b"!99212" + b"03"), b"< " + fr(b"#99212021C00000000002715"),
         b"> " + fr(b"!992320F1"), b"< " + fr(b"#99232"), b"> " + fr(b"!9926D0018" + rec)]
chunk = (b"\n".join(lines) + b"\n") * 1000
raw = b"".join(l[2:].replace(b"\\r\\n", b"\r\n") for l in lines) * 1000
for name, block in (("cap.log", chunk), ("cap.bin", raw)):
    with open(f"{d}/{name}", "wb") as f:
        n = 0
        while n < 200 * 1024 * 1024:
            f.write(block); n += len(block)
r = random.Random(5)
with open(f"{d}/t20k.csv", "w") as f:
    f.write("number,acceleration,deceleration,speed," + ",".join(f"axis{k}" for k in range(1, 9)) + "\n")
    mm = lambda v: ("-" if v < 0 else "") + "%d.%03d" % (abs(v) // 1000, abs(v) % 1000)
    for n in range(1, 20001):
        a, dcc, s = r.randrange(200), r.randrange(200), r.randrange(2000)
        pos = [mm(r.randrange(-2000000, 2000001)) for _ in range(8)]
        f.write(f"{n},{a // 100}.{a % 100:02d},{dcc // 100}.{dcc % 100:02d},{s}," + ",".join(pos) + "\n")
PY

for f in cap.log cap.bin; do
  size=$(stat -c %s "$dir/$f")
  /usr/bin/time -f "%e s, peak RSS %M kB" -o "$dir/time" "$iai" inspect "$dir/$f" | tail -1 || true
  echo "inspect $f ($size bytes): $(cat "$dir/time")"
done

"$iai" simulate --tcp 127.0.0.1:0 --quiet >"$dir/sim.log" &
sim=$!
for _ in $(seq 50); do [ -s "$dir/sim.log" ] && break; sleep 0.1; done
addr=$(head -1 "$dir/sim.log" | cut -d' ' -f3)
for verify in off full; do
  /usr/bin/time -f "%e" -o "$dir/time" "$iai" table write "$dir/t20k.csv" --tcp "$addr" --verify "$verify" 2>"$dir/err" >"$dir/out"
  echo "table write --verify $verify: $(cat "$dir/time") s wall; $(tail -1 "$dir/err"); $(cat "$dir/out")"
done
bytes=$(grep -o '[0-9]* bytes written' "$dir/err" | cut -d' ' -f1)
# 8N1: 10 bits a byte; the 26DH replies are 16 bytes each (852 frames or so).
python3 -c "b=$bytes; print(f'wire-limited minimum at 115,200 baud for the write alone: {b*10/115200:.1f} s ({b} bytes)')"
