"""The device-level conformance checks, one module per check (named as the check), and the
modules several of them share.

Every check opens a fresh driver from the :class:`~hcard_conformance.context.Context` and reads
STATE input reports (spec/device-protocol.md); the thresholds are those of spec/conformance.md.

Checks: :mod:`.friction` (``device.friction``, A1 on rendered friction), :mod:`.dynamics`
(D1 bandwidth, D2 rise time), :mod:`.latency` (D3), :mod:`.safety` (S1; PS1, PS5),
:mod:`.watchdog` (PS3, PS4), :mod:`.upload_integrity` (U1-U3), :mod:`.report_loss` (L1-L3),
:mod:`.session_ownership` (O1-O3), :mod:`.refusals` (X1), :mod:`.profile_upload` (U4-U5),
:mod:`.descriptor` (H1-H3: the HID report descriptor, which it reads through the driver's
descriptor requests rather than STATE reports) and :mod:`.host_driver` (HD1-HD4: the driver
class itself, on the scripted device of :mod:`.host_link`, its cases in :mod:`.host_versions`,
:mod:`.host_inputs` and :mod:`.host_sessions`). Shared: :mod:`.common` (the level, how a
measured metric is judged, conventions of the measurements), :mod:`.device_classes` (the plate
dynamics each device class requires), :mod:`.host_finger` (the host's finger on the surface),
:mod:`.link_session` (the finger playing while every STATE report is read) and
:mod:`.host_profiles` (the device profiles a check uploads, and the friction read through
one).

The registry names each check's function by import path
(:data:`hcard_conformance.registry.BUILTIN_CHECKS`): listing the checks imports none of these
modules.
"""
