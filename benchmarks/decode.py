"""The wire's hot decodes: today's ``frames.decode`` (msgpack in C, then one Python predicate
per frame over its fields) against msgspec's typed decoding (``msgspec.msgpack.Decoder`` over
``Struct``s, ``array_like``, tagged by kind: decoding and the field types checked in one C
call), and against msgpack's bare unpacking (the floor: no check at all), per kind and per
number of nodes a release carries.

msgspec's tagged union takes its tag from an array's first element, where today's frames
carry the wire's version: the candidate layout puts a tag (version and kind in one integer)
first. Both decoders get the same frames in their own layout; each figure is the median of
``--repeat`` interleaved rounds, ns a decode, and the ratio against today's in the same run.

    python benchmarks/decode.py [--n 2 4 8] [--repeat 5] [--count 20000] [--json] [--table FILE]
"""


import argparse
import json
import statistics
import sys
import time
from pathlib import Path
from typing import Any, Union

import msgpack

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import _table  # noqa: E402
from hycosim.core import frames  # noqa: E402

try:
    import msgspec
except ImportError:  # the bench extra
    msgspec = None


def _candidate_types() -> Any:
    """The hot kinds as msgspec Structs in the candidate layout ([tag, fields...])."""
    Value = Any  # as today's decode: each value's type is checked by the node that takes it

    def tag(kind: int) -> int:
        return (frames.VERSION << 8) | kind

    class Outputs(msgspec.Struct, array_like=True, tag=tag(frames.OUTPUTS), tag_field="tag"):
        uid: int
        step: int
        t: float
        values: list[Value]

    class Step(msgspec.Struct, array_like=True, tag=tag(frames.STEP), tag_field="tag"):
        step: int
        t: float
        h: float
        mode: str
        inputs: dict[str, list[Value]]
        driven: list[str]
        slopes: dict[str, list[Any]]

    class Batch(msgspec.Struct, array_like=True, tag=tag(frames.BATCH), tag_field="tag"):
        uid: int
        step: int
        t: float
        values: list[Value]
        earlier: list[list[Value]]

    return msgspec.msgpack.Decoder(Union[Outputs, Step, Batch]), tag


def frames_for(n: int) -> dict[str, tuple[list[Any], int]]:
    """Each hot kind's fields (after version and kind) as a release among ``n`` nodes carries them."""
    inputs = {f"node{i}": [0.5 * i, 1.25, 3] for i in range(n)}
    return {
        "OUTPUTS": ([3, 1234, 12.34, [0.25, 1.5, 7]], frames.OUTPUTS),
        "STEP": ([1234, 12.34, 0.01, "free", inputs, [], {}], frames.STEP),
        "BATCH": ([3, 1234, 12.34, [0.25, 1.5, 7], [[0.1, 1.0, 2], [0.2, 1.1, 3]]], frames.BATCH),
    }


def _time(decode, payload: bytes, count: int) -> float:
    """ns a decode, over ``count`` decodes."""
    began = time.perf_counter_ns()
    for _ in range(count):
        decode(payload)
    return (time.perf_counter_ns() - began) / count


def measure(n: int, repeat: int, count: int) -> list[dict[str, Any]]:
    """Nanoseconds a decode takes per frame kind and node count: ``frames.decode``, the typed msgspec
    candidate and msgpack alone, medians of ``repeat`` rounds of ``count`` decodes."""
    decoder, tag = _candidate_types() if msgspec is not None else (None, None)
    out = []
    for kind_name, (fields, kind) in frames_for(n).items():
        today = frames.encode(kind, *fields)
        candidate = msgpack.packb([tag(kind), *fields], use_bin_type=True) if tag else None
        unpack = (lambda p: msgpack.unpackb(p, raw=False, strict_map_key=False))
        rounds: dict[str, list[float]] = {"frames.decode": [], "msgspec": [], "msgpack floor": []}
        for _ in range(repeat):  # interleaved: each round measures all three
            rounds["frames.decode"].append(_time(frames.decode, today, count))
            if decoder is not None:
                rounds["msgspec"].append(_time(decoder.decode, candidate, count))
            rounds["msgpack floor"].append(_time(unpack, today, count))
        base = statistics.median(rounds["frames.decode"])
        for system, times in rounds.items():
            if times:
                out.append({"kind": kind_name, "n": n, "system": system, "ns": statistics.median(times),
                            "ratio": statistics.median(times) / base})
    return out


def main() -> None:
    """Measure and print the decodes (``--json``: one object a line)."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, nargs="+", default=[2, 4, 8])
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--count", type=int, default=20000)
    ap.add_argument("--json", action="store_true")
    _table.add_argument(ap)
    args = ap.parse_args()
    if msgspec is None:
        print("msgspec is not installed (pip install msgspec): only today's decode and the floor are measured",
              file=sys.stderr)
    rows = [row for n in args.n for row in measure(n, args.repeat, args.count)]
    _table.write(args.table, _table.Table(
        f"ns a decode, medians of {args.repeat} interleaved rounds of {args.count:,} decodes; × today: against "
        "frames.decode of the same frame in the same run:",
        ["kind", "nodes", "decoder", "ns", "× today"],
        [[r["kind"], str(r["n"]), r["system"], f"{r['ns']:.0f}", f"{r['ratio']:.2f}"] for r in rows]))
    if args.json:
        for row in rows:
            print(json.dumps(row))
        return
    print(f"{'kind':8} {'n':>3} {'decoder':15} {'ns':>8} {'× today':>8}")
    for row in rows:
        print(f"{row['kind']:8} {row['n']:>3} {row['system']:15} {row['ns']:8.0f} {row['ratio']:8.2f}")


if __name__ == "__main__":
    main()
