"""The `impairment` section of a scenario: lossy, late radio links for the simulated world.

A fault-injection section for `isac-mission sim` and `run` (the simulated vehicles' MAVLink and
the world's detections on Zenoh); the service never reads it. Every channel is one direction of
one link: random (Bernoulli) loss, a latency drawn uniformly in [latency - jitter, latency +
jitter], duplication (a second copy with its own latency) and reordering (a packet held back by
an extra `reorder_delay_ms`, so that the following ones overtake it). Times are milliseconds of
simulation time (docs/reliability.md, "Lossy, late radio links").

```yaml
impairment:
  seed: 7                      # default: the world's noise seed
  mavlink:                     # every vehicle, both directions (or uplink: / downlink:)
    loss: 0.2
    latency_ms: 100
    jitter_ms: 50
  vehicles:                    # per vehicle, replacing `mavlink` for that vehicle
    1: {downlink: {loss: 0.5}}
  detections: {loss: 0.1, latency_ms: 300, jitter_ms: 200}
```

The `sim` / `run` flag `--impair-link SPEC` takes the same fields as text:
`loss=0.2,latency_ms=100,jitter_ms=50` (both directions of every vehicle),
`1:down:loss=0.5` (vehicle 1's downlink), `detections:loss=0.1,latency_ms=300`.
"""

from __future__ import annotations

from typing import Any

from pydantic import Field, ValidationError, model_validator

from isac_mission.config.sections import Section
from isac_mission.config.validation import validation_lines
from isac_mission.errors import ConfigError


class ChannelImpairmentConfig(Section):
    """One direction of one link. Probabilities per packet; times in simulation ms."""

    loss: float = Field(0.0, ge=0, le=1, description="Probability that a packet is lost.")
    latency_ms: float = Field(0.0, ge=0, le=10_000, description="Mean one-way latency.")
    jitter_ms: float = Field(
        0.0, ge=0, description="Half-width of the uniform latency spread (<= latency_ms)."
    )
    duplicate: float = Field(
        0.0, ge=0, le=1, description="Probability that a delivered packet arrives twice."
    )
    reorder: float = Field(
        0.0, ge=0, le=1, description="Probability that a packet is held back (overtaken)."
    )
    reorder_delay_ms: float = Field(
        100.0, ge=0, le=10_000, description="Extra delay of a held-back packet."
    )

    @model_validator(mode="after")
    def _jitter_below_latency(self) -> ChannelImpairmentConfig:
        if self.jitter_ms > self.latency_ms:
            raise ValueError(
                f"jitter_ms ({self.jitter_ms:g}) must not exceed latency_ms ({self.latency_ms:g}): "
                "latencies are drawn in [latency - jitter, latency + jitter]"
            )
        return self

    @property
    def active(self) -> bool:
        """True when the channel changes anything (loss, delay, copies or reordering)."""
        return bool(self.loss or self.latency_ms or self.duplicate or self.reorder)


CHANNEL_FIELDS = tuple(ChannelImpairmentConfig.model_fields)
"""The keys of one channel: loss, latency_ms, jitter_ms, duplicate, reorder, reorder_delay_ms."""


class LinkImpairmentConfig(Section):
    """Both directions of a vehicle's MAVLink: uplink (to the vehicle) and downlink (from it).

    The channel keys given directly (`{loss: 0.2}`) apply to both directions."""

    uplink: ChannelImpairmentConfig = ChannelImpairmentConfig()
    downlink: ChannelImpairmentConfig = ChannelImpairmentConfig()

    @model_validator(mode="before")
    @classmethod
    def _both_directions(cls, data: Any) -> Any:
        if isinstance(data, dict) and any(k in CHANNEL_FIELDS for k in data):
            if "uplink" in data or "downlink" in data:
                raise ValueError(
                    "give either the channel keys (both directions) or uplink/downlink"
                )
            return {"uplink": data, "downlink": data}
        return data

    @property
    def active(self) -> bool:
        """True when either direction is impaired."""
        return self.uplink.active or self.downlink.active


class ImpairmentConfig(Section):
    """Fault injection on the simulated world's links (see the module docstring)."""

    seed: int | None = Field(
        None, ge=0, description="Seed of the impairment draws; null = the world's noise seed."
    )
    mavlink: LinkImpairmentConfig = LinkImpairmentConfig()
    vehicles: dict[int, LinkImpairmentConfig] = Field(
        default_factory=dict, description="Per vehicle index: replaces `mavlink` for it."
    )
    detections: ChannelImpairmentConfig = ChannelImpairmentConfig()

    @model_validator(mode="after")
    def _vehicle_indices(self) -> ImpairmentConfig:
        bad = sorted(m for m in self.vehicles if m < 0)
        if bad:
            raise ValueError(f"vehicles: indices must be >= 0 (got {bad})")
        return self

    def link_for(self, m: int) -> LinkImpairmentConfig:
        """Vehicle m's MAVLink impairment: its own entry, else the fleet's."""
        return self.vehicles.get(m, self.mavlink)

    @property
    def active(self) -> bool:
        """True when any link is impaired."""
        return (
            self.mavlink.active
            or any(v.active for v in self.vehicles.values())
            or self.detections.active
        )


def _parse_fields(text: str, spec: str) -> dict[str, float]:
    fields: dict[str, float] = {}
    for item in text.split(","):
        key, sep, value = item.partition("=")
        key = key.strip()
        if not sep or key not in CHANNEL_FIELDS:
            raise ConfigError(
                f"--impair-link {spec!r}: {item.strip()!r}: expected KEY=VALUE with KEY one of "
                f"{', '.join(CHANNEL_FIELDS)}"
            )
        try:
            fields[key] = float(value)
        except ValueError:
            raise ConfigError(
                f"--impair-link {spec!r}: {key}: not a number (got {value.strip()!r})"
            ) from None
    return fields


def apply_impairment_flags(
    base: ImpairmentConfig, specs: list[str] | tuple[str, ...]
) -> ImpairmentConfig:
    """`base` with each `--impair-link` SPEC applied in order (later ones win), validated.

    SPEC: `[TARGET:]KEY=VALUE[,KEY=VALUE...]` with TARGET `all` (default: every vehicle's
    MAVLink), `M` (vehicle M), optionally followed by `:up` or `:down` (one direction), or
    `detections`. Raises ConfigError naming the spec and the field at fault.
    """
    data = base.model_dump()
    for spec in specs:
        head, _, fields_text = spec.rpartition(":") if "=" in spec else ("", "", spec)
        parts = [p.strip() for p in head.split(":")] if head else []
        fields = _parse_fields(fields_text, spec)
        direction = parts.pop() if parts and parts[-1] in ("up", "down") else None
        target = parts[0] if parts else "all"
        if len(parts) > 1:
            raise ConfigError(f"--impair-link {spec!r}: expected [TARGET[:up|down]:]KEY=VALUE,...")
        if target == "detections":
            if direction is not None:
                raise ConfigError(f"--impair-link {spec!r}: detections have one direction")
            data["detections"] = {**data["detections"], **fields}
            continue
        if target == "all":
            link = data["mavlink"]
        elif target.isdigit():
            link = data["vehicles"].setdefault(int(target), dict(data["mavlink"]))
        else:
            raise ConfigError(
                f"--impair-link {spec!r}: target {target!r}: expected all, a vehicle index "
                "or detections"
            )
        for name in ("uplink", "downlink"):
            if direction is None or name.startswith(direction):
                link[name] = {**link[name], **fields}
    try:
        return ImpairmentConfig.model_validate(data)
    except ValidationError as err:
        raise ConfigError(validation_lines(err, "--impair-link")) from None
