"""The names of the built-in conformance checks, each spelled once (``level.what``, as the
verdicts print them).

The rows of :data:`hcard_conformance.registry.BUILTIN_CHECKS` give each name its level and
description; the check functions name their results with these constants, and the reference
device's negative controls name the check each one must fail. This module imports nothing, so
the registry can list the checks without importing a check module.
"""

from __future__ import annotations

FORMAT_PARSE = "format.parse"
FORMAT_ROUND_TRIP = "format.round_trip"
FORMAT_REJECT = "format.reject"
FORMAT_COMPAT = "format.compat"

RENDERER_EXACT = "renderer.exact"
RENDERER_FRICTION_ERROR = "renderer.friction_error"
RENDERER_COMPONENT_AMPLITUDE = "renderer.component_amplitude"
RENDERER_COMPONENT_FREQUENCY = "renderer.component_frequency"
RENDERER_SPATIAL_PHASE = "renderer.spatial_phase"
RENDERER_BOUNDARY = "renderer.boundary"

DEVICE_FRICTION = "device.friction"
DEVICE_DYNAMICS = "device.dynamics"
DEVICE_LATENCY = "device.latency"
DEVICE_SAFETY = "device.safety"
DEVICE_WATCHDOG = "device.watchdog"
DEVICE_UPLOAD_INTEGRITY = "device.upload-integrity"
DEVICE_REPORT_LOSS = "device.report-loss"
DEVICE_SESSION_OWNERSHIP = "device.session-ownership"
DEVICE_REFUSALS = "device.refusals"
DEVICE_PROFILE_UPLOAD = "device.profile-upload"
DEVICE_DESCRIPTOR = "device.descriptor"
DEVICE_HOST_DRIVER = "device.host-driver"
DEVICE_SATURATION = "device.saturation"
