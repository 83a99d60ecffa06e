"""Worker pools under a long temporary directory.

The forkserver listens on a socket at <TMPDIR>/pymp-XXXXXXXX/listener-XXXXXXXX, and
an AF_UNIX address holds 107 bytes on Linux (103 on macOS, whose TMPDIR is already
/var/folders/…/T/, about 50): under a deeper TMPDIR the server cannot bind and no
worker starts.  dynprop then starts its workers by spawn."""

import os
import subprocess
import sys

from scenarios.workers import forkserver_fits

POOL = """
from dynprop.scenarios.workers import clean_start_context, worker_pool
with clean_start_context(["dynprop.scenarios.workers"]) as ctx:
    with worker_pool(2, ctx) as pool:
        print(ctx.get_start_method(), sum(pool.map(abs, [-1, -2, -3])))
"""


def test_the_socket_fits_under_a_short_temporary_directory_only():
    assert forkserver_fits("/tmp")
    assert forkserver_fits("/" + "d" * 70)                  # 71 + 32 = 103 bytes
    assert not forkserver_fits("/" + "d" * 71)


def test_a_pool_starts_under_a_temporary_directory_too_long_for_its_socket(tmp_path):
    deep = tmp_path / ("d" * 50) / ("e" * 50)
    deep.mkdir(parents=True)
    assert not forkserver_fits(str(deep))
    proc = subprocess.run([sys.executable, "-c", POOL], env={**os.environ, "TMPDIR": str(deep)},
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert proc.stdout.split() == ["spawn", "6"]
    assert list(deep.iterdir()) == [], "the pool left its temporary files behind"
