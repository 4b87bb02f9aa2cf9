"""Make ``land-110m.json.gz``, the land outlines the station map of the report draws, from
Natural Earth 1:110m Admin 0 Countries (public domain).

Source used: the copy shipped as ``naturalearth_lowres`` in the geopandas 0.14.4 wheel
(``geopandas/datasets/naturalearth_lowres/*.shp``, made by geopandas'
``naturalearth_creation.py`` from https://www.naturalearthdata.com/ ne_110m_admin_0_countries).
Run once, outside the package's run time (needs ``pyshp``)::

    pip download --no-deps geopandas==0.14.4 && unzip geopandas-0.14.4-*.whl 'geopandas/datasets/*'
    pip install pyshp
    python src/overbound/data/make_land.py geopandas/datasets/naturalearth_lowres/naturalearth_lowres.shp

Output: gzip JSON ``{"source": ..., "rings": [[lon0, lat0, lon1, lat1, ...], ...]}``, each ring
one outer or inner boundary of a country's polygons, coordinates rounded to 0.01 degree. Written
with a fixed gzip time stamp: the same input gives the same bytes.
"""

from __future__ import annotations

import gzip
import io
import itertools
import json
import sys
from pathlib import Path


def rings(path: str) -> list[list[float]]:
    import shapefile  # pyshp: needed by this script only, not by the package

    out = []
    for shape in shapefile.Reader(path).shapes():
        bounds = [*shape.parts, len(shape.points)]
        for a, b in itertools.pairwise(bounds):
            out.append([round(c, 2) for point in shape.points[a:b] for c in point])
    return out


def main() -> None:
    doc = {
        "source": "Natural Earth 1:110m Admin 0 Countries (public domain), via geopandas 0.14.4 "
        "naturalearth_lowres",
        "rings": rings(sys.argv[1]),
    }
    raw = json.dumps(doc, separators=(",", ":")).encode()
    buf = io.BytesIO()
    with gzip.GzipFile(fileobj=buf, mode="wb", mtime=0, compresslevel=9) as gz:
        gz.write(raw)
    (Path(__file__).parent / "land-110m.json.gz").write_bytes(buf.getvalue())
    print(f"{len(doc['rings'])} rings, {len(raw)} bytes, {len(buf.getvalue())} compressed")


if __name__ == "__main__":
    main()
