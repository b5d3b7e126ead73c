"""End-to-end jobs behind the CLI: scan (capture, decode, reconstruct), evaluate, turntable,
demo. Each step is a library function; the CLI only parses arguments and prints."""
