"""Replay one fuzz case and show its full traceback.

    python -m tests.fuzz.replay READER SEED INDEX    # case INDEX of corpus/READER/SEED
    python -m tests.fuzz.replay READER SEED          # the stored seed itself
    python -m tests.fuzz.replay READER --file PATH   # any file (or folder) as READER's input

``READER`` is a name of :data:`tests.fuzz.targets.TARGETS`; for ``store`` the seed is
``store-zarr`` or ``store-png`` (made in a temporary folder first) or an overlay of
``corpus/store``. ``--write DIR`` also
writes the case's input there, to edit it into a regression seed
(``corpus/READER/regress-*``).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import traceback
from pathlib import Path

from tests.fuzz.cases import file_name, load_seed, store_case, tiny_stores
from tests.fuzz.mutate import mutation
from tests.fuzz.targets import CORPUS, TARGETS, read_folder, run_case, write_input


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("reader", choices=sorted(TARGETS))
    parser.add_argument("seed", nargs="?")
    parser.add_argument("index", nargs="?", type=int)
    parser.add_argument("--file", type=Path, help="a file or folder to read instead")
    parser.add_argument("--write", type=Path, help="write the case's input into this folder")
    args = parser.parse_args(argv)
    target = TARGETS[args.reader]
    with tempfile.TemporaryDirectory(prefix="virtus-replay-") as scratch:
        if args.file is not None:
            data = read_folder(args.file) if args.file.is_dir() else args.file.read_bytes()
            name = file_name(target, args.file.name)
            what = f"the file {args.file}"
        else:
            if args.seed is None:
                parser.error("give a seed (or --file)")
            if args.reader == "store":
                seed = store_case(tiny_stores(Path(scratch) / "stores"), args.seed)
            else:
                seed = load_seed(target, CORPUS / args.reader / args.seed)
            name = file_name(target, args.seed)
            if args.index is None:
                data, what = seed, "the stored seed"
            else:
                suffix = Path(args.seed).suffix.lower()
                data, what = mutation(args.reader, args.seed, seed, args.index, suffix)
        print(f"{args.reader}: {what}", file=sys.stderr)
        if args.write is not None:
            args.write.mkdir(parents=True, exist_ok=True)
            print(f"input written to {write_input(data, name, args.write)}", file=sys.stderr)
        try:
            result = run_case(target, data, name, Path(scratch) / "case")
        except Exception:  # noqa: BLE001 (shown in full)
            traceback.print_exc()
            print("FAILURE: an exception outside the allow-list", file=sys.stderr)
            return 1
    print(f"ok: {result}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
