"""DeepSpline's curve networks (seed 002, section 4), small enough to train on a CPU.

:mod:`.models` the encoder and the V / M / MV decoders, :mod:`.train` their loss, batches
and ``nurbskit train curves``, :mod:`.predict` the shipped weights at work
(``nurbskit.curves_from_image(..., method="network")``).
"""
