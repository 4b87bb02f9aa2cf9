"""DO-229 SBAS user engine (issue 6): message layer and engine core.

* the received messages come from the readers of :mod:`overbound.io` as
  :class:`~overbound.io.sbas_frames.SbasFrames` (EMS: :func:`overbound.io.ems.read_ems`; with the
  CRC-24Q check of :mod:`overbound.io.sbas_crc` and the bit fields of :mod:`overbound.io.sbas_bits`);
* :mod:`overbound.sbas.messages` - decoding of MT 0-7, 9, 10, 12, 17, 18, 24-28 into tables;
* :mod:`overbound.sbas.igp` - the IGP band grid of the MT 18 mask;
* :mod:`overbound.sbas.engine` - :func:`~overbound.sbas.engine.run_sbas`, corrected ranges,
  variances, errors and protection levels (with :mod:`~overbound.sbas.corrections`,
  :mod:`~overbound.sbas.iono`, :mod:`~overbound.sbas.tropo`, :mod:`~overbound.sbas.solution`).
"""
