"""End-to-end jobs behind the CLI, each a library function that takes a
:class:`virtus.scanner.Scanner`: scan (capture, decode, reconstruct), evaluate, turntable,
calibrate (rendered or real captures), twin (digital twins and their validation), ablation,
demo. The CLI only parses arguments, builds the scanner and prints."""
