"""Imported first by the warm-start fork server (repro/launch/warm.py ``PRELOAD``), and only there: the server
dies with the launcher that started it (PR_SET_PDEATHSIG), so that its forked runs, which get SIGTERM when the
server dies, die with the launcher too, as the plain path's children do. (Without it the server outlives a killed
launcher: every run it forked holds the pipe whose end-of-file would tell it to exit.)"""

import ctypes
import os
import signal

try:
    ctypes.CDLL("libc.so.6", use_errno=True).prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG
except OSError:  # not Linux: the server then exits when its last run has ended
    pass
if os.getppid() == 1:  # the launcher was gone before the line above ran
    os._exit(0)
