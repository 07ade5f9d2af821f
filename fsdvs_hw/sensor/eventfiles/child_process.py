"""HDF5 / AEDAT4 writers and the AEDAT4 reader, run as a child process
(``python -P child_process.py write FORMAT PATH WIDTH HEIGHT METADATA_JSON`` / ``... read PATH``).

dv-processing and HDF5 are C/C++ libraries: an error deep inside them can end the process
instead of raising (dv-processing ``abort()``s; h5py segfaulted at exit after a write failed
with EFBIG, measured). :class:`fsdvs_hw.sensor.eventfiles.eventfile.EventFileWriter` therefore runs them
here, in a child process that imports only numpy and h5py or dv-processing, and feeds it events
through a pipe; if this process fails or dies, the parent reports the file and the reason or
signal, and the partial file is removed. Reading runs here too: a corrupt file can make dv-processing loop
forever inside ``getNextEventBatch`` (measured: a file with 5 garbled bytes), which the parent
ends after a timeout.

Protocol (stdin, little-endian): messages of an int64 count ``n`` followed by ``n`` int64 times
(µs), ``n`` int16 x, ``n`` int16 y and ``n`` uint8 polarities (1 ON / 0 OFF). ``n = -1`` commits:
the writer is closed, the file flushed and fsync'ed, and the process exits 0. End of input
without the commit message (the parent was killed) removes the file and exits 3; a
failure (full disk) prints one line on stderr, removes the file and exits 4.
Reading writes to stdout: one byte ``R`` once started (imports done), int64 width, height, the camera name's length and UTF-8 bytes, then
batches in the message layout above, then ``-1``. A file dv-processing refuses: the message on
stderr and exit status 2.
"""

from __future__ import annotations

import os
import signal
import sys

__all__: list[str] = []

#: Rows (events) per HDF5 chunk of the ``.h5`` layout: v2e's ``--dvs_h5`` value.
H5_CHUNK_ROWS = 65536


def _read_array(stream, n: int, dtype: str):
    """``n`` items of ``dtype`` read from ``stream`` straight into a new array (EOFError if it ends first)."""
    import numpy as np

    out = np.empty(n, dtype=dtype)
    view = out.data.cast("B")
    got = 0
    while got < len(view):
        k = stream.readinto(view[got:])
        if not k:
            raise EOFError
        got += k
    return out


def read(path: str) -> int:
    """Stream the events of AEDAT4 file ``path`` to stdout (layout in the module docstring)."""
    import dv_processing as dv
    import numpy as np

    out = sys.stdout.buffer
    out.write(b"R")  # started: the parent's start-up wait ends, its per-batch timeout begins
    out.flush()
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


def _h5_writer(path: str, width: int, height: int, metadata: dict) -> tuple:
    import collections
    from concurrent.futures import ThreadPoolExecutor

    import h5py
    import numpy as np
    from isal import isal_zlib

    f = h5py.File(path, "w")
    # v2e's layout (events (N, 4) uint32, chunks of 65 536 rows, gzip), with HDF5's byte shuffle and
    # gzip level 1: about half the writer's CPU of v2e's level 4 for a smaller file (docs/speed.md);
    # every HDF5 reader undoes both filters itself
    ds = f.create_dataset(
        "events",
        shape=(0, 4),
        maxshape=(None, 4),
        dtype="uint32",
        chunks=(H5_CHUNK_ROWS, 4),
        compression="gzip",
        compression_opts=1,
        shuffle=True,
    )
    attrs = {
        "width": width,
        "height": height,
        "time_unit": "us",
        "polarity": "1 = ON, 0 = OFF (v2e)",
        "columns": "t_us, x, y, p",
        **metadata,
    }
    for k, v in attrs.items():
        f.attrs[k] = v

    # The filters' work runs on two threads: each whole chunk is shuffled here exactly as HDF5's
    # shuffle filter would (element size 4), deflated into a standard zlib stream by ISA-L (level 1:
    # ~17 ns per event against zlib's ~140 at level 1, files of the same size; docs/speed.md) and
    # written with write_direct_chunk, in order; the dataset records shuffle + deflate, so every
    # HDF5 reader decodes it with its own zlib.
    rows = int(ds.chunks[0])
    pool = ThreadPoolExecutor(2, thread_name_prefix="h5-deflate")
    pending: collections.deque = collections.deque()  # (first row, future of the chunk's bytes)
    held: list = []  # rows not yet in a whole chunk
    state = {"rows": 0}  # rows handed to the pool

    def deflate(block) -> bytes:
        full = block if len(block) == rows else np.concatenate([block, np.zeros((rows - len(block), 4), np.uint32)])
        shuffled = np.ascontiguousarray(full).view(np.uint8).reshape(-1, 4).T.tobytes()
        return isal_zlib.compress(shuffled, 1)

    def submit(block) -> None:
        first = state["rows"]
        state["rows"] = first + len(block)
        ds.resize(state["rows"], axis=0)
        pending.append((first, pool.submit(deflate, block)))

    def drain(keep: int) -> None:
        while len(pending) > keep:
            first, fut = pending.popleft()
            ds.id.write_direct_chunk((first, 0), fut.result())

    def write(t, x, y, p) -> None:
        block = np.empty((t.size, 4), dtype=np.uint32)
        block[:, 0], block[:, 1], block[:, 2], block[:, 3] = t, x, y, p
        held.append(block)
        n = sum(len(b) for b in held)
        if n < rows:
            return
        whole = np.concatenate(held) if len(held) > 1 else held[0]
        cut = n - n % rows
        for i in range(0, cut, rows):
            submit(whole[i : i + rows])
        held[:] = [whole[cut:]] if cut < n else []
        drain(4)  # at most a few chunks (1 MiB each) in flight

    def close() -> None:
        if held:
            submit(np.concatenate(held))  # the edge chunk, zero-padded as HDF5 stores it
        drain(0)
        pool.shutdown()
        f.flush()
        f.close()

    return write, close


def _aedat4_writer(path: str, width: int, height: int, metadata: dict) -> tuple:
    import dv_processing as dv

    cfg = dv.io.MonoCameraWriter.EventOnlyConfig("fsdvs_hw", (width, height))
    state = {"writer": dv.io.MonoCameraWriter(path, cfg)}

    def write(t, x, y, p) -> None:
        t, x, y, p = t.tolist(), x.tolist(), y.tolist(), p.astype(bool).tolist()
        for i in range(0, len(t), 1 << 16):  # dv-processing has no bulk numpy input
            store = dv.EventStore()
            push = store.push_back
            sl = slice(i, i + (1 << 16))
            for a, b, c, d in zip(t[sl], x[sl], y[sl], p[sl]):
                push(a, b, c, d)
            state["writer"].writeEvents(store)

    def close() -> None:
        del state["writer"]  # flushes and closes the file

    return write, close


def _fail(path: str, exc: BaseException, status: int) -> None:
    """Report ``exc`` in one line, remove the partial file, and exit at once: no finalizers (h5py
    can crash closing a file whose last write failed)."""
    sys.stderr.write(f"{type(exc).__name__}: {' '.join(str(exc).split())[:300]}\n")
    sys.stderr.flush()
    try:
        os.unlink(path)
    except OSError:
        pass
    os._exit(status)


def main(argv: list[str]) -> int:
    """``write FORMAT PATH WIDTH HEIGHT METADATA_JSON``: write the events arriving on stdin
    (FORMAT ``hdf5`` or ``aedat4``); ``read PATH``: see :func:`read`."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the parent decides what a Ctrl-C means
    mode, argv = argv[0], argv[1:]
    if mode == "read":
        return read(argv[0])
    import json

    fmt, path, width, height = argv[0], argv[1], int(argv[2]), int(argv[3])
    try:
        write, close = (_h5_writer if fmt == "hdf5" else _aedat4_writer)(path, width, height, json.loads(argv[4]))
    except Exception as exc:  # noqa: BLE001  reported to the parent
        _fail(path, exc, 4)
    stdin = sys.stdin.buffer
    try:
        while True:
            n = int(_read_array(stdin, 1, "<i8")[0])
            if n < 0:
                break
            t, x, y, p = (_read_array(stdin, n, dt) for dt in ("<i8", "<i2", "<i2", "u1"))
            write(t, x, y, p)
        close()
        fd = os.open(path, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)
    except EOFError:  # the parent went away without committing: leave nothing behind
        _fail(path, EOFError("no commit from the parent"), 3)
    except Exception as exc:  # noqa: BLE001  full disk and the like: reported to the parent
        _fail(path, exc, 4)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
