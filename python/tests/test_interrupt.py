"""The GIL is released while the volume is prepared and the model evolves (another Python thread runs
meanwhile), and Ctrl-C (SIGINT) raises KeyboardInterrupt within a second, in the metric stage as in the
evolution."""
import os
import signal
import subprocess
import sys
import textwrap
import threading
import time

import riemesh

# A run of several seconds: the paper's phantom at 96^3 meshed with delta 0.8 (about 16k vertices,
# about 390 iterations; the metric stage takes about 0.3 s of it, 0.1 s at 64^3).
LONG_RUN = textwrap.dedent("""
    import sys, riemesh
    volume = riemesh.phantom("cube-cavity", size=int(sys.argv[1]), noise=0.5)
    print("go", flush=True)
    riemesh.mesh(volume, delta=0.8)
    print("finished", flush=True)
""")


def interrupt_after(delay, size=96):
    """Seconds from SIGINT to the end of a long run interrupted `delay` seconds after it started, and
    the child's output."""
    child = subprocess.Popen([sys.executable, "-c", LONG_RUN, str(size)], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                             text=True, env=dict(os.environ))
    assert child.stdout.readline().strip() == "go"
    time.sleep(delay)
    sent = time.monotonic()
    child.send_signal(signal.SIGINT)
    out, err = child.communicate(timeout=30)
    return time.monotonic() - sent, child.returncode, out, err


def test_ctrl_c_raises_keyboard_interrupt_within_a_second_while_evolving():
    latency, code, out, err = interrupt_after(1.0)
    assert "finished" not in out  # still running when the signal came
    assert code != 0 and "KeyboardInterrupt" in err
    assert latency < 1.0, latency


def test_ctrl_c_raises_keyboard_interrupt_within_a_second_in_the_metric_stage():
    latency, code, out, err = interrupt_after(0.02, size=64)
    assert "finished" not in out
    assert code != 0 and "KeyboardInterrupt" in err
    assert latency < 1.0, latency


def test_other_python_threads_run_while_meshing():
    volume = riemesh.phantom("cube-cavity", size=64, noise=0.5)
    ticks = 0
    running = True

    def count():
        nonlocal ticks
        while running:
            ticks += 1
            time.sleep(0.001)

    thread = threading.Thread(target=count)
    thread.start()
    time.sleep(0.05)
    start_ticks, start = ticks, time.monotonic()
    riemesh.mesh(volume, delta=1.5)
    seconds = time.monotonic() - start
    during = ticks - start_ticks
    running = False
    thread.join()
    # A thread that sleeps 1 ms per tick makes at most seconds / 1 ms ticks; with the GIL held by
    # mesh() it would make none until it returns.
    assert seconds > 0.1
    assert during > 0.3 * seconds / 0.0011, (during, seconds)
