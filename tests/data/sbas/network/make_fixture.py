"""Copy the EGNOS day's products into tests/data/sbas/network (gzip without name or time stamp).

    python tests/data/sbas/network/make_fixture.py /path/to/shared/data/egnos-ems-prn123-2019-014

Run from the repository root. The EMS hours are concatenated in order, as the data set's
PROVENANCE suggests (``cat ems/h*.ems``).
"""

from __future__ import annotations

import gzip
import shutil
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent


def main(src: Path) -> None:
    for name in ("igs20361.sp3", "igsg0140.19i"):
        (HERE / f"{name}.gz").write_bytes(gzip.compress((src / name).read_bytes(), 9, mtime=0))
    shutil.copyfile(src / "P1C11901.DCB", HERE / "P1C11901.DCB")
    hours = b"".join(p.read_bytes() for p in sorted((src / "ems").glob("h*.ems")))
    (HERE / "egnos123_2019014.ems.gz").write_bytes(gzip.compress(hours, 9, mtime=0))


if __name__ == "__main__":
    main(Path(sys.argv[1]))
