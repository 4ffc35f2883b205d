"""Imported first by the warm-start fork server (repro/launch/warm.py ``PRELOAD``), and only there: the server
dies with the launcher that started it (PR_SET_PDEATHSIG), so that its forked runs, which get SIGTERM when the
server dies, die with the launcher too, as the plain path's children do. (Without it the server outlives a killed
launcher: every run it forked holds the pipe whose end-of-file would tell it to exit.)"""

import os
import signal

from repro.launch.runner import die_with_parent

die_with_parent(signal.SIGKILL)  # not on Linux: the server then exits when its last run has ended
if os.getppid() == 1:  # the launcher was gone before the line above ran
    os._exit(0)
