"""Peak resident memory of the current process, for the benchmarks' children.

`resource.getrusage(RUSAGE_SELF).ru_maxrss` is not enough for a process started by
`subprocess`: Linux folds the high-water mark of the memory image that `exec` replaces into
it, and with `vfork` (which Python's `subprocess` uses where it can) that image is the
parent's, so a child lighter than its parent reports the parent's peak. The peak of the
process's own image is `VmHWM` in `/proc/self/status`; elsewhere `ru_maxrss` is used.
"""

import resource


def peak_rss_mb() -> float:
    """The peak resident set of this process's own memory image, in MiB."""
    try:
        with open("/proc/self/status") as status:
            for line in status:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) / 1024
    except OSError:
        pass
    scale = 1024 if resource.getrusage(resource.RUSAGE_SELF).ru_maxrss else 1
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / scale
