# Shared by the reply forger's labs: write a made-up "passed" reply for the probe that is
# running onto the probe's pipe (found among this process's file descriptors), then exit, so
# the probe's own code never reports. FORGE = False is the same submission without the trick.
import fcntl
import os
import stat
import sys

FORGE = True


def probe_frame(name):
    """The frame of the grader's probe ``name`` calling into this submission, or None."""
    frame = sys._getframe(1)
    while frame is not None:
        if frame.f_code.co_name == name:
            return frame
        frame = frame.f_back
    return None


def forge(value):
    """Send ``value`` as the probe's reply and end the process (when FORGE)."""
    if not FORGE:
        return
    from course.grading import wire

    data = wire.dumps({"value": wire.encode(value), "output": ""})
    for fd in range(3, 1024):
        try:
            if not stat.S_ISFIFO(os.fstat(fd).st_mode):
                continue
            if fcntl.fcntl(fd, fcntl.F_GETFL) & os.O_ACCMODE != os.O_WRONLY:
                continue
            os.write(fd, len(data).to_bytes(8, "little") + data)
        except OSError:
            continue
    os._exit(0)
