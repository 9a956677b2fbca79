"""The conformance suite's faulty device: ``faulty://FAULT?strength=S``, one fault at one
strength, each in a physical unit, so that every threshold of the suite can be shown to bite
above it and to hold below it (spec/conformance.md section 6, QN2; the table in
:mod:`.known_faults`).

It is a frame device with a vendor's driver, registered through the ``hcard.plugins`` entry
point ``faulty-device`` exactly as a vendor's package is (:mod:`.plugin`): the hardware is
simulated on its own clock (:mod:`.plate`, device faults), the card is rendered on the host by
the host library's :class:`~hcard.device.frame_driver.FrameDriver` (:mod:`.driver`; driver
faults in :mod:`.host_faults`), and the device publishes its physics profile
(:mod:`.profile`). The faults and the URI grammar are :mod:`.faults`. It needs nothing of the
reference device.
"""
