"""DO-229 SBAS user engine (issue 6): message layer and engine core.

* :mod:`overbound.sbas.frames` - :class:`~overbound.sbas.frames.SbasFrames`, received messages
  from any reader (EMS: :func:`overbound.io.ems.read_ems`);
* :mod:`overbound.sbas.crc` - CRC-24Q parity check;
* :mod:`overbound.sbas.bits` - vectorised bit-field extraction;
* :mod:`overbound.sbas.messages` - decoding of MT 0-7, 9, 10, 12, 17, 18, 24-28 into tables;
* :mod:`overbound.sbas.igp` - the IGP band grid of the MT 18 mask;
* :mod:`overbound.sbas.engine` - :func:`~overbound.sbas.engine.run_sbas`, corrected ranges,
  variances, errors and protection levels (with :mod:`~overbound.sbas.corrections`,
  :mod:`~overbound.sbas.iono`, :mod:`~overbound.sbas.tropo`, :mod:`~overbound.sbas.solution`).
"""
