"""The contracts of the plugin kinds: one :class:`typing.Protocol` per kind, and the table of
the kinds (:data:`KIND_TABLE`) from which the hooks, the registry and ``hcard plugins`` take them.

A plugin object is anything a hook of :mod:`hcard.plugins.hookspecs` returns; it must match
the Protocol of its kind. The Protocols are ``runtime_checkable``, so ``isinstance(obj,
PredictorPlugin)`` checks that the members are there (not their signatures). Base classes with
shared behaviour implement them and may be subclassed: :class:`Encoder` (here),
:class:`hcard.physics.Predictor`, :class:`hcard.physics.effects.Effect`,
``hcard.device.Driver`` and ``hcard_conformance.registry.Check``.

Every kind has ``kind`` (its name in :data:`KINDS`), ``name`` (unique within the kind) and a
one-line ``description``. This module imports nothing heavy: the types of the members are only
named for type checkers.
"""

from __future__ import annotations

import abc
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, ClassVar, NamedTuple, Protocol, runtime_checkable

from hcard.plugins.lazy_command import LazyCommand
from hcard.v1 import card_pb2 as pb

if TYPE_CHECKING:
    import click
    import numpy as np

    from hcard.physics.predictor import Parameter, Variable


@runtime_checkable
class Plugin(Protocol):
    """What every plugin object has, whatever its kind."""

    @property
    def kind(self) -> str:
        """The kind, one of :data:`KINDS`."""

    @property
    def name(self) -> str:
        """Unique within the kind, e.g. ``"image"``."""

    @property
    def description(self) -> str:
        """One line: what it does."""


@dataclass
class EncodeResult:
    """What an encoder produced: the card and figures for the summary.

    ``stats`` holds named figures (for example ``rms_error``), ``log`` lines of notes, ``maps``
    per-taxtel arrays of shape (rows, cols) (for example ``error_rms``, relative friction).
    """

    card: pb.Card
    stats: dict[str, Any] = field(default_factory=dict)
    log: list[str] = field(default_factory=list)
    maps: dict[str, Any] = field(default_factory=dict)


@runtime_checkable
class EncoderPlugin(Plugin, Protocol):
    """Kind ``encoder`` (hook ``hcard_encoders``): turns a source file into a card.

    ``hcard encode`` reaches the encoder through this contract only: it hands its options to
    :meth:`options` first (a bad one is a usage error before any file is read), then what that
    returns to :meth:`encode`, with ``progress``.
    """

    def options(self, **values: Any) -> dict[str, Any]:
        """``values`` checked, with the encoder's defaults filled in: the keyword options
        :meth:`encode` then takes. The names are the encoder's own (``hcard encode`` passes its
        options by their long names with ``_`` for ``-``, e.g. ``taxtel_mm``). Raise
        :class:`~hcard.errors.UsageError` naming the option by that name when one is unknown,
        out of range or does not fit with another."""

    def encode(self, source: Path, *, progress: Callable[[str], None] | None = None,
               **options: Any) -> EncodeResult:
        """Encode ``source``; ``options`` are encoder specific. ``progress``, when given, is
        called with one line of text at each stage of a long encode (an encoder may say
        nothing). Raise an HcardError on bad input."""


class Encoder(abc.ABC):
    """Base class of encoders (an :class:`EncoderPlugin`): subclasses define ``encode``, and
    ``options`` when they can check their options before reading the source."""

    kind: ClassVar[str] = "encoder"
    name: ClassVar[str] = ""
    description: ClassVar[str] = ""

    def options(self, **values: Any) -> dict[str, Any]:
        """``values`` as given: this encoder checks its options when it encodes."""
        return dict(values)

    @abc.abstractmethod
    def encode(self, source: Path, *, progress: Callable[[str], None] | None = None,
               **options: Any) -> EncodeResult:
        """Encode ``source``; see :meth:`EncoderPlugin.encode`."""


@runtime_checkable
class PredictorPlugin(Plugin, Protocol):
    """Kind ``predictor`` (hook ``hcard_predictors``): a physics model mapping actuation and
    finger state to an output (relative friction, a force), and back. SI units throughout.

    Implemented by :class:`hcard.physics.Predictor`, which checks inputs against
    :attr:`inputs` and reads and writes device-profile objects.
    """

    @property
    def parameters(self) -> tuple[Parameter, ...]:
        """The model's parameters: name, unit, default, bounds and thesis source."""

    @property
    def inputs(self) -> tuple[Variable, ...]:
        """The variables :meth:`forward` takes (name, SI unit, default)."""

    @property
    def output(self) -> Variable:
        """What :meth:`forward` returns."""

    @property
    def inverse_input(self) -> str | None:
        """The input :meth:`inverse` solves for (``"amplitude"``, ``"voltage"``), or None."""

    @property
    def params(self) -> dict[str, float]:
        """Parameter values by name (their units)."""

    def forward(self, **inputs: Any) -> np.ndarray:
        """The output for inputs broadcast together; vectorised."""

    def inverse(self, target: Any, **inputs: Any) -> np.ndarray:
        """The value of :attr:`inverse_input` that makes the output equal ``target``."""

    def with_params(self, **changes: float) -> PredictorPlugin:
        """A copy with some parameters changed."""

    def to_profile(self) -> dict[str, Any]:
        """The ``predictor`` object of a device profile: model name and parameters."""


@runtime_checkable
class EffectPlugin(Plugin, Protocol):
    """Kind ``calibration-effect`` (hook ``hcard_calibration_effects``): a physical effect a
    fitted predictor may lack, which calibration can add (spec/calibration.md).

    Implemented by :class:`hcard.physics.effects.Effect`, whose transforms default to the
    identity.
    """

    @property
    def reason(self) -> str:
        """Why its absence leaves a residual."""

    @property
    def signature(self) -> tuple[str, ...]:
        """Regressors the residual of its absence shows against."""

    @property
    def parameters(self) -> tuple[Parameter, ...]:
        """The effect's own parameters."""

    @property
    def inputs(self) -> tuple[Variable, ...]:
        """Inputs it adds to the model it augments."""

    @property
    def neutral(self) -> dict[str, float]:
        """Parameter values at which it is off exactly."""

    def applies_to(self, base: Any) -> str | None:
        """Why it cannot augment the predictor ``base``, or None."""

    def transform_inputs(
        self, inputs: Mapping[str, np.ndarray], params: Mapping[str, float]
    ) -> dict[str, np.ndarray]:
        """The inputs the base model sees."""

    def transform_params(
        self,
        params: Mapping[str, Any],
        inputs: Mapping[str, np.ndarray],
        effect_params: Mapping[str, float],
        per_sample: frozenset[str] = ...,
    ) -> dict[str, Any]:
        """The base model's parameter values its forward map uses."""

    def transform_output(
        self, output: np.ndarray, inputs: Mapping[str, np.ndarray], params: Mapping[str, float]
    ) -> np.ndarray:
        """The augmented output from the base output."""

    def transform_output_of(
        self,
        quantity: str,
        output: np.ndarray,
        inputs: Mapping[str, np.ndarray],
        params: Mapping[str, float],
    ) -> np.ndarray:
        """:meth:`transform_output` for a base whose output is ``quantity``."""


@runtime_checkable
class DriverPlugin(Plugin, Protocol):
    """Kind ``driver`` (hook ``hcard_drivers``): a transport to devices of some URI schemes.

    The plugin object is usually a class (``hcard.device.Driver`` subclass) whose
    ``open`` returns a connected instance, or a :class:`~hcard.plugins.lazy_plugins.LazyDriver`
    naming that class, imported when a device is first opened (the built-ins).
    """

    @property
    def schemes(self) -> tuple[str, ...]:
        """URI schemes it opens, e.g. ``("sim",)``."""

    def open(self, uri: Any, *, timeout_s: float = ...) -> Any:
        """Connect to the device ``uri`` names (a ``DeviceUri``); raise a DeviceError."""

    def enumerate(self, hosts: Sequence[tuple[str, int]] = ..., *,
                  timeout_s: float = ...) -> list[Any]:
        """``DeviceListing`` of every device it reaches now; never raises for a missing one."""


@runtime_checkable
class DeviceProfilePlugin(Plugin, Protocol):
    """Kind ``device-profile`` (hook ``hcard_device_profiles``): the physics profile a kind of
    device renders with and publishes (spec/device-profile.md), recognised from its DEVICE_INFO.

    A host that plays a card on a device with its own profile writes this profile into the
    recording's sidecar (spec/measurement-format.md MF9), where ``hcard calibrate`` finds the
    base model to calibrate (:func:`hcard.device.published_profiles.published_profile`).
    """

    def matches(self, info: Any) -> bool:
        """True when the device ``info`` (a ``DeviceInfo``) describes renders with it."""

    def profile(self) -> Any:
        """The profile (:class:`hcard.physics.profile.DeviceProfile`)."""


@runtime_checkable
class CheckPlugin(Plugin, Protocol):
    """Kind ``conformance-check`` (hook ``hcard_conformance_checks``): one check of the
    conformance suite, ``hcard_conformance.registry.Check`` for the built-ins."""

    @property
    def level(self) -> str:
        """``format``, ``renderer`` or ``device``."""

    def run(self, ctx: Any) -> Iterable[Any]:
        """``CheckResult`` objects, one per case, on the conformance ``Context`` ``ctx``."""


@dataclass(frozen=True)
class Loss:
    """What a target format cannot hold of a card, as an export states it.

    Attributes:
        field: the card's property lost, one of :data:`LOSS_FIELDS` (``"channel"``,
            ``"locking"``, ``"orientation"``, ``"friction-scale"``, ``"phase"``, ...).
        detail: one line: what the format does instead, with the card's values.
        carried: where the export keeps it anyway (an extension the format allows, e.g. the
            PNG text chunk ``hcard``), or ``""`` when it is gone.
    """

    field: str
    detail: str
    carried: str = ""

    def as_json(self) -> dict[str, str]:
        """The loss as a JSON object (``hcard export --json``)."""
        return {"field": self.field, "detail": self.detail, "carried": self.carried}


LOSS_FIELDS = ("channel", "locking", "orientation", "friction-scale", "phase", "taxtel-map",
               "components", "metadata")
"""The properties of a card an export may lose (spec/interchange.md section 1)."""


@dataclass
class ExportResult:
    """What an exporter produced: the files to write and what the format could not hold.

    Attributes:
        files: ``(suffix, bytes)`` pairs: the main file first (its suffix ``""``: written to
            the output path as given), then companions written beside it as the output path
            with its suffix replaced (``".gltf"``). ``hcard export`` writes them all or none.
        losses: what the target format cannot hold of this card.
        stats: named figures for the summary (resolution, sizes, fidelity in JND).
    """

    files: list[tuple[str, bytes]]
    losses: list[Loss] = field(default_factory=list)
    stats: dict[str, Any] = field(default_factory=dict)


@runtime_checkable
class ImporterPlugin(Plugin, Protocol):
    """Kind ``importer`` (hook ``hcard_importers``): reads another tool's asset into a card.

    ``hcard import`` picks the importer by content (:meth:`recognises`, on the file's first
    :data:`SNIFF_BYTES`) or by name (``--from``), checks its options (:meth:`options`) before
    reading the file, then calls :meth:`read`. The result's ``stats`` hold the fidelity of the
    card to the source in JND (``rms_error_jnd``, ``max_error_jnd``), as ``hcard encode``'s.
    """

    @property
    def suffixes(self) -> tuple[str, ...]:
        """File suffixes of the format, lower case with the dot (``(".haps",)``)."""

    def recognises(self, head: bytes) -> int:
        """How surely ``head`` (the file's first bytes) is this format: 0 not, 1 the container
        fits (a PNG: several bitmap formats share it), 2 certain (a key only it uses)."""

    def options(self, **values: Any) -> dict[str, Any]:
        """``values`` checked with the importer's defaults filled in; raise
        :class:`~hcard.errors.UsageError` naming the option when one is bad."""

    def read(self, source: Path, *, progress: Callable[[str], None] | None = None,
             **options: Any) -> EncodeResult:
        """The card of ``source``; raise an HcardError naming the file and field on bad
        input (in bounded time and memory, whatever the file holds)."""


@runtime_checkable
class ExporterPlugin(Plugin, Protocol):
    """Kind ``exporter`` (hook ``hcard_exporters``): writes a card in another tool's format.

    ``hcard export --to NAME`` checks the options (:meth:`options`), then calls :meth:`write`
    and writes the files it returns atomically, all or none."""

    @property
    def suffix(self) -> str:
        """The main file's usual suffix (``".hjif"``)."""

    def options(self, **values: Any) -> dict[str, Any]:
        """``values`` checked with the exporter's defaults filled in (UsageError if bad)."""

    def write(self, card: pb.Card, *, progress: Callable[[str], None] | None = None,
              **options: Any) -> ExportResult:
        """The files of ``card`` in this format and what the format cannot hold of it."""


SNIFF_BYTES = 4096
"""Bytes of a file ``hcard import`` hands to :meth:`ImporterPlugin.recognises`."""


@runtime_checkable
class CommandPlugin(Protocol):
    """A subcommand of ``hcard`` (hook ``hcard_commands``), loaded only when it runs.

    :class:`LazyCommand` is the usual implementation: ``hcard --help`` lists ``name`` and
    ``summary`` without importing the command's module. The command closes what it opens
    (files, devices, sockets; ``with`` blocks) before it returns: the console script exits
    without the interpreter's final garbage collection (:func:`hcard.cli.main.main`), so an
    object left in a reference cycle is not finalized and a file left open in one is not
    flushed.
    """

    @property
    def name(self) -> str:
        """The subcommand, e.g. ``"device"``."""

    @property
    def summary(self) -> str:
        """The first sentence of its help: the line ``hcard --help`` lists."""

    def load(self) -> click.Command:
        """The click command (importing its module)."""


class Kind(NamedTuple):
    """One plugin kind, as a row of :data:`KIND_TABLE`.

    Attributes:
        name: the kind's name, the ``kind`` of its plugin objects (``"encoder"``).
        hook: the hook returning its plugin objects (``"hcard_encoders"``,
            :mod:`hcard.plugins.hookspecs`).
        protocol: the Protocol its plugin objects implement.
        attribute: the :class:`~hcard.plugins.registry.PluginRegistry` property giving them
            by name (``"encoders"``).
        description: what the hook returns, in words (the hook's and the property's
            documentation).
    """

    name: str
    hook: str
    protocol: type
    attribute: str
    description: str


KIND_TABLE: tuple[Kind, ...] = (
    Kind("encoder", "hcard_encoders", EncoderPlugin, "encoders",
         "encoders: objects turning a source (image, recipe, recording) into a card"),
    Kind("predictor", "hcard_predictors", PredictorPlugin, "predictors",
         "physics predictors: actuation and finger state to friction, and back"),
    Kind("driver", "hcard_drivers", DriverPlugin, "drivers",
         "device drivers: transports that upload cards and stream tracks to a device"),
    Kind("device-profile", "hcard_device_profiles", DeviceProfilePlugin, "device_profiles",
         "device profiles: the physics a kind of device renders with, from its DEVICE_INFO"),
    Kind("calibration-effect", "hcard_calibration_effects", EffectPlugin, "calibration_effects",
         "calibration effects: physical effects a fitted model may lack"),
    Kind("conformance-check", "hcard_conformance_checks", CheckPlugin, "conformance_checks",
         "conformance checks run by ``hcard conformance``"),
    Kind("importer", "hcard_importers", ImporterPlugin, "importers",
         "importers: readers of other tools' assets (bitmaps, .haps, .hjif) into cards"),
    Kind("exporter", "hcard_exporters", ExporterPlugin, "exporters",
         "exporters: writers of cards in other tools' formats"),
)
"""Every plugin kind: its name, its hook, its Protocol, its registry property and what it is,
in the order ``hcard plugins`` lists them. The hooks (:mod:`hcard.plugins.hookspecs`), the
registry's properties and lookups (:mod:`hcard.plugins.registry`) and the names below are made
from it; a new kind is a new row (and its Protocol above)."""

KINDS: tuple[str, ...] = tuple(kind.name for kind in KIND_TABLE)
"""Plugin kinds, in the order ``hcard plugins`` lists them."""

PROTOCOL_OF_KIND: dict[str, type] = {kind.name: kind.protocol for kind in KIND_TABLE}
"""The Protocol each kind of :data:`KINDS` implements."""

KIND_OF_HOOK: dict[str, Kind] = {kind.hook: kind for kind in KIND_TABLE}
"""The kind whose plugin objects each hook returns, by hook name."""

KIND_NAMED: dict[str, Kind] = {kind.name: kind for kind in KIND_TABLE}
"""Each kind by its name."""

__all__ = [
    "KINDS",
    "KIND_NAMED",
    "KIND_OF_HOOK",
    "KIND_TABLE",
    "LOSS_FIELDS",
    "PROTOCOL_OF_KIND",
    "SNIFF_BYTES",
    "CheckPlugin",
    "CommandPlugin",
    "DeviceProfilePlugin",
    "DriverPlugin",
    "EffectPlugin",
    "EncodeResult",
    "Encoder",
    "EncoderPlugin",
    "ExportResult",
    "ExporterPlugin",
    "ImporterPlugin",
    "Kind",
    "LazyCommand",
    "Loss",
    "Plugin",
    "PredictorPlugin",
]
