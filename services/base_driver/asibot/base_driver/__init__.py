"""Pioneer P3-AT base driver over ARCOS (pyserial URLs), and an ARCOS emulator for tests and demos
(the `emulator` package). Facts and their sources: docs/arcos.md."""
