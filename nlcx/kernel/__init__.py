"""The compiled simulation kernel: one code path for single runs and sweeps.

- :mod:`nlcx.kernel.abi`: what plugins compile against: the signatures of plants,
  controllers, controller callbacks and loop elements, the hook points and the status codes.
- :mod:`nlcx.kernel.structures`: the kernel's arguments and work spaces as named structures
  (the plant, the controller, the loop elements, the records, ...), read by name.
- :mod:`nlcx.kernel.integrator`: the closed loop stepped in lock step over a batch of variants.
- :mod:`nlcx.kernel.working_storage`: its working slots, signals and stage columns, built in
  numpy before a call, and their compaction as variants stop.
- :mod:`nlcx.kernel.friction`: the stick-slip friction physics of Appendix A, the plant-force
  element the integrator calls for the variants that have friction.
"""
