#!/usr/bin/env python3
"""Cross-checks the hand-written fixtures in tests/fixtures.rs against DUNE's IMC.

Every fixture must deserialize with DUNE (`imcpy`, the Python bindings of DUNE-IMC:
`pip install imcpy`), and every little-endian one must be exactly what DUNE writes
when it serializes the message again. Not run by `cargo test` (no Python there);
run it after changing a fixture:

    python3 protocols/imc-proto/scripts/dune-crosscheck.py
"""
import pathlib
import re
import sys

import imcpy

FIXTURES = pathlib.Path(__file__).resolve().parent.parent / "tests" / "fixtures.rs"


def fixtures():
    src = FIXTURES.read_text()
    for name, body in re.findall(r"const (\w+): &\[u8\] = &\[(.*?)\];", src, re.S):
        body = re.sub(r"//[^\n]*", "", body)
        tokens = re.findall(r"b'.'|0x[0-9A-Fa-f]{2}", body)
        yield name, bytes(ord(t[2]) if t.startswith("b'") else int(t, 16) for t in tokens)


def main():
    failures = 0
    count = 0
    for name, data in fixtures():
        count += 1
        try:
            msg = imcpy.Packet.deserialize(data)
        except Exception as e:  # DUNE raises its own exception types
            print(f"{name}: DUNE refuses it: {e}")
            failures += 1
            continue
        if name.endswith("_LE") and bytes(msg.serialize()) != data:
            print(f"{name}: DUNE serializes it differently: {bytes(msg.serialize()).hex()}")
            failures += 1
        else:
            print(f"{name}: ok ({msg.msg_name})")
    if count == 0:
        print("no fixtures found")
        return 1
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
