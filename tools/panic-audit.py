#!/usr/bin/env python3
"""Lists the panic calls left in a firmware image, by the function each
comes from, and fails unless every one comes from a reviewed function of
a dependency (smoltcp, httparse).

Usage: tools/panic-audit.py ELF REVIEWED

ELF is the no-panic program built with the `no-panic-audit` feature and
without tail merging, so that each panic keeps its own call and line:

    cargo rustc --release -p firmware-example --no-default-features \
      --features no-panic-audit --bin no_panic_proof \
      --target thumbv7m-none-eabi -- -C llvm-args=-enable-tail-merge=false

that is the link-time proof's program (firmware-example/src/bin/
no_panic_proof.rs) with smoltcp's interface and sockets linked in as
well, which the link-time proof cannot take. REVIEWED
(firmware-example/no-panic-smoltcp.txt) lists the smoltcp functions (and
the few of httparse, the web page's request parser) whose panics were
read, each group with the reason it cannot fire here.

How: the panic handler, `core::panicking`'s functions and every function
of Rust's own library that calls one of them, directly or through
another, are panic entry points (`panic_bounds_check`, `unwrap_failed`,
...); each call to one of them from any other function is a panic site.
The site's debug information gives the chain of inlined frames at the
call, innermost first; the first function that is neither Rust's library
nor a crate smoltcp keeps its data through (byteorder, heapless) is where
the panic comes from. A site fails the audit when that function is this
project's, or a dependency's function not in REVIEWED. A call the compiler kept without a line
of its own is judged by the code that reaches it (the branches to it and
the instruction before it); tail merging off, they are fewer.

Prints the sites per function, then `panic-audit: N sites (U without a
line of their own, ...), all in reviewed functions of smoltcp and
httparse (M); none in this project's code` or each
failing site with its frames, and exits 1 on a failure. Needs
arm-none-eabi-objdump, -nm and -addr2line (binutils-arm-none-eabi).
"""

import collections
import re
import subprocess
import sys

OUR_CRATES = ("firmware_example", "iai_protocol_b", "no_panic_proof")
LIBRARY_CRATES = ("core", "alloc")
# `<usize>::checked_sub`, `<[T]>::get`, `<&mut T as ...>`: methods of
# the library's own types.
PRIMITIVE = re.compile(r"^(?:[iu](?:8|16|32|64|128|size)|bool|char|str|\[|&|\*)")
LIBRARY_FNS = ("core::", "<core::", "alloc::", "<alloc::")
# Crates smoltcp writes and keeps its tables through: a panic in them is
# its caller's.
HELPER_CRATES = ("byteorder", "heapless")
BRANCH = re.compile(
    r"^\s+([0-9a-f]+):\s+(b|bl|blx|b\.[nw]|b(?:eq|ne|cs|hs|cc|lo|mi|pl|vs|vc|hi|ls|ge|lt|gt|le)(?:\.[nw])?|cbz|cbnz)\s+(?:r\d+, )?([0-9a-f]+)\s"
)
ENDS_FLOW = re.compile(r"^\s+[0-9a-f]+:\s+(b|b\.[nw]|bx|pop|ldmia\.w\s+sp!)\b(?!.*\bit\b)")


def run(*args):
    return subprocess.run(args, check=True, capture_output=True, text=True).stdout


def functions(elf):
    """Each function's start address -> (name, [(site, target, is_call)],
    {address: previous instruction's address if it falls through})."""
    funcs = {}
    current = None
    last = None
    for line in run("arm-none-eabi-objdump", "-d", "--no-show-raw-insn", elf).splitlines():
        m = re.match(r"^([0-9a-f]+) <(.+)>:$", line)
        if m:
            current = int(m.group(1), 16)
            funcs[current] = (m.group(2), [], {})
            last = None
            continue
        m = re.match(r"^\s+([0-9a-f]+):", line)
        if not m or current is None:
            continue
        addr = int(m.group(1), 16)
        if last is not None:
            funcs[current][2][addr] = last
        last = None if ENDS_FLOW.match(line) else addr
        m = BRANCH.match(line)
        if m:
            funcs[current][1].append((addr, int(m.group(3), 16), m.group(2) in ("bl", "blx")))
    return funcs


def demangled(elf):
    """Start address -> demangled name."""
    names = {}
    for line in run("arm-none-eabi-nm", "-C", elf).splitlines():
        parts = line.split(" ", 2)
        if len(parts) == 3 and parts[1] in "tT":
            names[int(parts[0], 16) & ~1] = parts[2]
    return names


def entry_points(funcs, names):
    """The panic handler and the library functions that reach it."""
    entries = {
        a
        for a, n in names.items()
        if n.endswith("rust_begin_unwind") or n.startswith("core::panicking::")
    }
    if not entries:
        sys.exit("panic-audit: no panic handler or core::panicking function in the image")
    library = {a for a, n in names.items() if n.startswith(LIBRARY_FNS)}
    grew = True
    while grew:
        grew = False
        for addr, (_, calls, _) in funcs.items():
            if addr in entries or addr not in library:
                continue
            if any(t in entries for _, t, _ in calls):
                entries.add(addr)
                grew = True
    return entries


class Lines:
    """addr2line's inlined frames at an address, innermost first, cached."""

    def __init__(self, elf):
        self.elf = elf
        self.cache = {}

    def chain(self, addr):
        if addr not in self.cache:
            out = run("arm-none-eabi-addr2line", "-e", self.elf, "-f", "-C", "-i", hex(addr)).splitlines()
            self.cache[addr] = list(zip(out[0::2], out[1::2]))
        return self.cache[addr]


def crate_of(function):
    """The crate a demangled function name belongs to (`<A as B>::f` is
    A's)."""
    name = function.lstrip("<")
    return name.split("::", 1)[0]


def owner(frames):
    """Whose panic the frames show: the innermost function that is not
    Rust's library or a helper crate. ("smoltcp", function), ("ours",
    function), ("other", function), or None when every frame is the
    library's."""
    for function, _ in frames:
        crate = crate_of(function)
        if crate in LIBRARY_CRATES or crate in HELPER_CRATES or PRIMITIVE.match(crate):
            continue
        if crate in OUR_CRATES:
            return ("ours", function)
        if crate == "smoltcp":
            return ("smoltcp", function)
        return ("other", function)
    return None


def merged(frames):
    """Whether a call has no line of its own (a block the compiler shares
    between several panics)."""
    return not frames or frames[0][1].endswith(":?") or frames[0][1].startswith("??")


def attribute(lines, func, site, seen=None):
    """The owners of a panic call at `site` in `func`: its own frames, or,
    where the compiler merged several panics into one call and kept no
    line for it, the owners of the code that reaches it (the branches to
    it and the instruction before it)."""
    seen = seen if seen is not None else set()
    if site in seen or len(seen) > 64:
        return []
    seen.add(site)
    frames = lines.chain(site)
    found = None if merged(frames) else owner(frames)
    if found is not None:
        return [found]
    _, calls, previous = func
    reach = [a for a, t, is_call in calls if t == site and not is_call]
    if site in previous:
        reach.append(previous[site])
    result = []
    for a in reach:
        result += attribute(lines, func, a, seen)
    return result or [("unknown", hex(site))]


def main():
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    elf, reviewed_path = sys.argv[1], sys.argv[2]
    reviewed = set()
    with open(reviewed_path) as f:
        for line in f:
            line = line.split("#", 1)[0].strip()
            if line:
                reviewed.add(line)
    funcs = functions(elf)
    names = demangled(elf)
    entries = entry_points(funcs, names)
    lines = Lines(elf)
    by_line = collections.Counter()
    failures = []
    sites = 0
    unlined = 0
    for addr, func in funcs.items():
        if addr in entries:
            continue
        for site, target, is_call in func[1]:
            if target not in entries:
                continue
            sites += 1
            unlined += merged(lines.chain(site))
            text = "\n".join(f"      {f} {loc}" for f, loc in lines.chain(site))
            for kind, where in set(attribute(lines, func, site)):
                if kind in ("smoltcp", "other") and where in reviewed:
                    by_line[where] += 1
                elif kind in ("smoltcp", "other"):
                    failures.append(f"  {hex(site)}: {where} is not in {reviewed_path}\n{text}")
                else:
                    failures.append(f"  {hex(site)}: {kind} {where}\n{text}")
    for line, n in sorted(by_line.items()):
        print(f"{n:3} site(s) in {line}")
    if failures:
        print(f"panic-audit: {len(failures)} of {sites} panic sites fail:")
        print("\n".join(failures))
        sys.exit(1)
    print(
        f"panic-audit: {sites} sites ({unlined} without a line of their own, judged by the code "
        f"that reaches them), all in reviewed functions of smoltcp and httparse ({len(by_line)}); "
        "none in this "
        "project's code"
    )


if __name__ == "__main__":
    main()
