"""Process tuning: glibc's allocator keeps per-frame buffers in the heap; GIL switch interval."""

from __future__ import annotations

import subprocess
import sys

import pytest

_FAULTS = """
import resource, sys
import numpy as np
from humanpt.runtime.tuning import tune_allocator
if sys.argv[1] == "tuned":
    assert tune_allocator()
keep = []
def frame(i):  # the shape of a lock-step frame: big temporaries, an image that lives on, small objects
    img = np.zeros((480, 640), np.float32) + i
    idx = np.arange(307200, dtype=np.int64)
    keep.append(np.empty(307200, np.uint8))
    if len(keep) > 3:
        keep.pop(0)
    small = [np.ones(10) for _ in range(100)]
    return float(img.ravel()[idx].sum()) + len(small)
frame(0)
r0 = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
for i in range(50):
    frame(i)
print(resource.getrusage(resource.RUSAGE_SELF).ru_minflt - r0)
"""


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc mallopt is Linux only")
def test_tuned_allocator_stops_page_faults_on_per_frame_buffers():
    def faults(mode):
        out = subprocess.run([sys.executable, "-c", _FAULTS, mode], capture_output=True, text=True, check=True)
        return int(out.stdout.split()[-1])

    plain, tuned = faults("plain"), faults("tuned")
    # Untuned (glibc defaults) the freed heap top goes back to the kernel and comes back
    # page by page: ~1400 faults a frame here; tuned, almost none.
    assert plain > 50 * 200, plain
    assert tuned < plain / 10, (plain, tuned)


def test_tune_process_sets_a_short_switch_interval():
    """In a subprocess: the switch interval (and the allocator) are process-wide, and this
    process's tests must keep Python's defaults."""
    code = ("import sys; from humanpt.runtime.tuning import tune_process; "
            "print(sys.getswitchinterval()); tune_process(); print(sys.getswitchinterval())")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    before, after = (float(v) for v in out.stdout.split())
    assert before == pytest.approx(0.005)  # Python's default: the call is what changed it
    assert after == pytest.approx(0.0005)  # 0.5 ms, as the module's docstring states
