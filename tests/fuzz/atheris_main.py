"""Coverage-guided fuzzing of one reader with atheris (libFuzzer for Python); not run in CI.

    .venv/bin/python -m pip install atheris
    .venv/bin/python -m tests.fuzz.atheris_main sequence --suffix .yaml -- \\
        -max_total_time=3600 -timeout=20 /tmp/corpus-sequence tests/fuzz/corpus/sequence

The first argument names a reader of ``tests/fuzz/targets.py`` (``python -m
tests.fuzz.atheris_main --list``); what follows ``--`` goes to libFuzzer (a writable corpus
folder first, then seed folders: ``tests/fuzz/corpus/<reader>``). ``--suffix`` picks the
format of one-file readers (default: the reader's first). For the folder readers (``capture``,
``calibration_txt``, ``store``) the input replaces one file of a seed folder (its first byte
picks which; ``--seed-folder`` picks the folder, default the reader's first seed; ``store``
makes its tiny store first), so give them an empty corpus folder.

Exceptions outside the reader's allow-list escape :func:`run_case` and atheris reports them
with the input (``crash-*`` files); replay one with ``python -m tests.fuzz.replay READER
--file crash-...`` and keep it as ``tests/fuzz/corpus/READER/regress-<what>.<suffix>`` once
fixed.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path


def main(argv: list[str] | None = None) -> None:
    argv = sys.argv[1:] if argv is None else argv
    ours, libfuzzer = (
        (argv[: argv.index("--")], argv[argv.index("--") + 1 :]) if "--" in argv else (argv, [])
    )
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("reader", nargs="?")
    parser.add_argument("--suffix", help="file suffix of a one-file reader (.yaml, .json, ...)")
    parser.add_argument("--seed-folder", type=Path, help="the folder a folder reader mutates")
    parser.add_argument("--list", action="store_true", help="list the readers and exit")
    args = parser.parse_args(ours)

    if args.list or args.reader is None:
        from tests.fuzz.targets import TARGETS as readers

        print("\n".join(sorted(readers)))
        return
    try:
        import atheris
    except ImportError:
        sys.exit("atheris is not installed: .venv/bin/python -m pip install atheris")

    with atheris.instrument_imports(include=["virtus"]):
        import virtus.calib.io  # noqa: F401 (instrumented for coverage)
        import virtus.capture  # noqa: F401
        import virtus.data  # noqa: F401
        import virtus.io.images  # noqa: F401
        import virtus.io.ply  # noqa: F401
        import virtus.io.safeio  # noqa: F401
        import virtus.patterns  # noqa: F401
        import virtus.scene.model  # noqa: F401
        import virtus.sensor  # noqa: F401

    from tests.fuzz.cases import seed_paths, tiny_stores
    from tests.fuzz.targets import TARGETS, read_folder, run_case, usd_available

    if args.reader not in TARGETS:
        sys.exit(f"unknown reader {args.reader!r}; one of {', '.join(sorted(TARGETS))}")
    if args.reader == "usd" and not usd_available():
        sys.exit("usd-core is not installed: pip install -e '.[usd]'")
    target = TARGETS[args.reader]
    scratch = Path(tempfile.mkdtemp(prefix="virtus-atheris-"))
    workdir = scratch / "case"

    if target.folder:
        if args.seed_folder is not None:
            base = read_folder(args.seed_folder)
        elif args.reader == "store":
            base = read_folder(tiny_stores(scratch / "stores")["zarr"])
        else:
            base = read_folder(seed_paths(args.reader)[0])
        names = sorted(base)

        def one_input(data: bytes) -> None:
            if not data:
                return
            files = dict(base)
            files[names[data[0] % len(names)]] = data[1:]
            run_case(target, files, "input", workdir)

    else:
        suffix = args.suffix or target.suffixes[0]

        def one_input(data: bytes) -> None:
            run_case(target, data, "input" + suffix, workdir)

    atheris.Setup([sys.argv[0], *libfuzzer], one_input)
    atheris.Fuzz()


if __name__ == "__main__":
    main()
