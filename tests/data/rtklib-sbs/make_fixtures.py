"""Build the RTKLIB ``.sbs`` fixtures of tests/data/rtklib-sbs/ (see PROVENANCE.md there).

Run from the repository root with the path of an RTKLIB ``convbin`` binary (built outside this
repository, see PROVENANCE.md) and a C compiler on the PATH::

    python tests/data/rtklib-sbs/make_fixtures.py /path/to/convbin

Not run by the tests. RTKLIB 2.4.2 resolves the 10-bit GPS week of broadcast ephemerides (and the
NovAtel week) with ``adjgpsweek``, which takes the week nearest to the *computer's clock*: run in
2026, the 2008 ephemerides come out dated 2028. So convbin runs with a two-function ``LD_PRELOAD``
shim that sets the clock (``gettimeofday``, ``time``) to 2008-05-31 00:00 UTC; ``adjgpsweek``
then resolves week 1481 (2008) and 1562 (2009), and the RINEX ``PGM / RUN BY / DATE`` line is
the same on every run, so every output is the same byte for byte. The input logs are copied into
a temporary directory first, so that the RINEX ``log:`` comment names the file, not this machine's
path. Outputs are gzipped with no name and time stamp (``gzip -9 -n`` equivalent).
"""

from __future__ import annotations

import gzip
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

OUT = Path(__file__).resolve().parent
SOURCE = Path(__file__).resolve().parents[4] / "shared" / "data" / "rtklib-rcvraw-msas-2008-147"
#: (log, convbin receiver format, outputs to keep) per source log.
LOGS = (
    ("ubx_20080526.ubx", "ubx", (".sbs",)),
    ("cres_20080526.bin", "hemis", (".obs", ".nav", ".sbs")),
    ("oemv_200911218.gps", "nov", (".sbs",)),
)
_FIXED_CLOCK = r"""
#include <sys/time.h>
#include <time.h>
static const time_t FIXED = 1212192000; /* 2008-05-31 00:00:00 UTC */
int gettimeofday(struct timeval *tv, void *tz)
{ (void)tz; if (tv) { tv->tv_sec = FIXED; tv->tv_usec = 0; } return 0; }
time_t time(time_t *t) { if (t) *t = FIXED; return FIXED; }
"""


def write_gz(path: Path, data: bytes) -> None:
    path.write_bytes(gzip.compress(data, compresslevel=9, mtime=0))


def convbin_command(convbin: str, log: str, fmt: str) -> list[str]:
    """The convbin command line: L1 only, with SNR, RINEX 2.11 obs and nav, RTKLIB SBAS log."""
    stem = Path(log).stem
    return [
        convbin, "-r", fmt, log, "-f", "1", "-os",
        "-o", f"{stem}.obs", "-n", f"{stem}.nav", "-s", f"{stem}.sbs", "-d", ".",
    ]  # fmt: skip


def main() -> None:
    convbin = str(Path(sys.argv[1]).resolve())
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        (work / "fixed_clock.c").write_text(_FIXED_CLOCK)
        shim = work / "fixed_clock.so"
        subprocess.run(
            ["cc", "-shared", "-fPIC", "-O2", "-o", str(shim), "fixed_clock.c"], cwd=work, check=True
        )
        env = {"LD_PRELOAD": str(shim), "PATH": "/usr/bin:/bin"}
        for log, fmt, keep in LOGS:
            shutil.copyfile(SOURCE / log, work / log)
            cmd = convbin_command(convbin, log, fmt)
            print(" ".join([Path(cmd[0]).name, *cmd[1:]]))
            subprocess.run(cmd, cwd=work, env=env, check=True, capture_output=True)
            for ext in keep:
                name = Path(log).stem + ext
                write_gz(OUT / f"{name}.gz", (work / name).read_bytes())
    # The u-blox log itself: the independent cross-check reads its frames with overbound's own reader.
    write_gz(OUT / "ubx_20080526.ubx.gz", (SOURCE / "ubx_20080526.ubx").read_bytes())


if __name__ == "__main__":
    main()
