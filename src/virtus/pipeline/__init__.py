"""End-to-end jobs behind the CLI, each a library function that takes a
:class:`virtus.scanner.Scanner` (or real data): capture (one capture rendered, or imported
from a real bench), scan (capture, decode, reconstruct), evaluate, turntable, calibrate
(rendered or real captures), twin (digital twins and their validation), ablation, demo.
Each job owns its run directory. The CLI only parses arguments, builds the scanner, calls
one job and prints."""
