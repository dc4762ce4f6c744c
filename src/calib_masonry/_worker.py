"""One call in a process of its own: ``python -m calib_masonry._worker`` reads a pickled
``(function, args)`` from its stdin, calls it, and writes the pickled ``("done", value)`` (or
``("error", message)``) to its stdout.

For pure-Python work that would hold the GIL against the caller's own thread (the simulation
geometry of a large build, beside the meshes, model.blend and figures): on a thread the two ran one
after the other in effect (measured: the geometry of an 8,190-brick tower took 43 s alone and 57 s
on a thread beside the build's 20 s of writing). A fresh interpreter (not a fork: the caller may
hold Blender's libraries and BLAS threads; nor the standard library's spawn start method: it imports
the caller's ``__main__`` again, which a user's script without a main guard would run twice).

The process ends when its caller's end of stdin closes (the caller finished, stopped or died), so it
never outlives the caller's work. What the called function prints goes to stderr (its progress
lines, as on a thread); stdout carries only the result.
"""

from __future__ import annotations

import os
import pickle
import signal
import sys
import threading
import traceback


def main() -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the caller stops it (Ctrl-C reaches both)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    out = os.fdopen(os.dup(1), "wb")
    os.dup2(2, 1)  # print() and C code writing to fd 1: onto stderr, not into the result
    sys.stdout = sys.stderr
    stdin = sys.stdin.buffer
    try:
        fn, args = pickle.load(stdin)
    except Exception:  # noqa: BLE001 - the caller closed before sending: nothing to do
        os._exit(0)

    def watch() -> None:
        stdin.read()  # returns at end of file: the caller closed its end (done, stopped or gone)
        os._exit(0)

    threading.Thread(target=watch, daemon=True).start()
    try:
        reply = ("done", fn(*args))
    except BaseException as exc:  # noqa: BLE001 - the caller computes again, where the error shows
        reply = ("error", f"{type(exc).__name__}: {exc}\n{traceback.format_exc()}")
    try:
        pickle.dump(reply, out, protocol=pickle.HIGHEST_PROTOCOL)
        out.flush()
    except (BrokenPipeError, OSError):
        pass
    os._exit(0)  # none of the caller's exit handlers, no waiting for the watcher


if __name__ == "__main__":
    main()
