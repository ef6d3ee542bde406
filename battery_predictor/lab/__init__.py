"""The emulation lab: the stand-in for the paper's test bench (seed paper section 4, step 2).

Nothing here is measured. The lab replaces the physical battery packs, the EA
PSB 10060-120 power supplies and the type-K thermocouples of the paper by

* :mod:`.real_pack` -- a reference "real pack" that is deliberately richer
  than the single particle model being fitted (SPMe cells, lumped thermal
  model, contact resistance, seeded cell-to-cell spread of capacity,
  resistance and cooling), simulated cell by cell with liionpack;
* :mod:`.instruments` -- the data acquisition: 10 Hz sampling, instrument
  noise, 0.01 V / 0.1 A quantisation, thermocouple noise, and the paper's
  5 s time-window averaging;
* :mod:`.experiments` -- the catalogue of emulated experiments that produces
  every shipped bag in ``bags/`` deterministically
  (``battery-predictor lab make-bags``).
"""

#: Version of the lab emulation; stored in every bag's metadata. Bump it when
#: a change alters the generated data.
LAB_VERSION = "1.0"

__all__ = ["LAB_VERSION"]
