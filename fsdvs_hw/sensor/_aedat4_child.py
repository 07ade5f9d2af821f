"""AEDAT4 writer and reader run as a child process (``python -P _aedat4_child.py write PATH WIDTH
HEIGHT`` / ``... read PATH``).

dv-processing is a C++ library: an error deep inside it (a full disk, a corrupt state) can
``abort()`` the process instead of raising. :class:`fsdvs_hw.sensor.eventfile.EventFileWriter`
therefore runs it here, in a child process that imports only numpy and dv-processing, and feeds
it events through a pipe; if this process dies, the parent reports the file and the signal and
removes the partial file. Reading runs here too: a corrupt file can make dv-processing loop
forever inside ``getNextEventBatch`` (measured: a file with 5 garbled bytes), which the parent
ends after a timeout.

Protocol (stdin, little-endian): messages of an int64 count ``n`` followed by ``n`` int64 times
(µs), ``n`` int16 x, ``n`` int16 y and ``n`` uint8 polarities (1 ON / 0 OFF). ``n = -1`` commits:
the writer is closed, the file flushed and fsync'ed, and the process exits 0. End of input
without the commit message (the parent was killed) removes the file and exits 3.
Reading writes to stdout: int64 width, height, the camera name's length and UTF-8 bytes, then
batches in the message layout above, then ``-1``. A file dv-processing refuses: the message on
stderr and exit status 2.
"""

from __future__ import annotations

import os
import signal
import sys

__all__: list[str] = []


def _read_exact(stream, n: int) -> bytes:  # type: ignore[no-untyped-def]
    buf = bytearray()
    while len(buf) < n:
        block = stream.read(n - len(buf))
        if not block:
            raise EOFError
        buf += block
    return bytes(buf)


def read(path: str) -> int:
    """Stream the events of AEDAT4 file ``path`` to stdout (layout in the module docstring)."""
    import dv_processing as dv
    import numpy as np

    out = sys.stdout.buffer
    try:
        rec = dv.io.MonoCameraRecording(path)
        if not rec.isEventStreamAvailable():
            raise RuntimeError("has no event stream")
        w, h = rec.getEventResolution()
        name = rec.getCameraName().encode("utf-8", "replace")
        out.write(np.array([w, h, len(name)], dtype="<i8").tobytes() + name)
        while rec.isRunning():
            batch = rec.getNextEventBatch()
            if batch is None:
                break
            a = batch.numpy()
            parts = [np.int64(a.size).astype("<i8").tobytes()]
            for k, dt in (("timestamp", "<i8"), ("x", "<i2"), ("y", "<i2"), ("polarity", "u1")):
                parts.append(np.ascontiguousarray(a[k], dtype=dt).tobytes())
            out.write(b"".join(parts))
    except RuntimeError as exc:
        sys.stderr.write(" ".join(str(exc).split())[:300] + "\n")
        return 2
    out.write(np.int64(-1).astype("<i8").tobytes())
    out.flush()
    return 0


def main(argv: list[str]) -> int:
    """``write PATH WIDTH HEIGHT``: write the events arriving on stdin; ``read PATH``: see :func:`read`."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the parent decides what a Ctrl-C means
    mode, argv = argv[0], argv[1:]
    if mode == "read":
        return read(argv[0])
    import dv_processing as dv
    import numpy as np

    path, width, height = argv[0], int(argv[1]), int(argv[2])
    cfg = dv.io.MonoCameraWriter.EventOnlyConfig("fsdvs_hw", (width, height))
    writer = dv.io.MonoCameraWriter(path, cfg)
    stdin = sys.stdin.buffer
    try:
        while True:
            n = int(np.frombuffer(_read_exact(stdin, 8), dtype="<i8")[0])
            if n < 0:
                break
            t = np.frombuffer(_read_exact(stdin, 8 * n), dtype="<i8").tolist()
            x = np.frombuffer(_read_exact(stdin, 2 * n), dtype="<i2").tolist()
            y = np.frombuffer(_read_exact(stdin, 2 * n), dtype="<i2").tolist()
            p = np.frombuffer(_read_exact(stdin, n), dtype="u1").astype(bool).tolist()
            for i in range(0, n, 1 << 16):  # dv-processing has no bulk numpy input
                store = dv.EventStore()
                push = store.push_back
                for a, b, c, d in zip(t[i:i + (1 << 16)], x[i:i + (1 << 16)], y[i:i + (1 << 16)], p[i:i + (1 << 16)]):
                    push(a, b, c, d)
                writer.writeEvents(store)
    except EOFError:  # the parent went away without committing: leave nothing behind
        del writer
        try:
            os.unlink(path)
        except OSError:
            pass
        return 3
    del writer  # flushes and closes the file
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
