"""Scenario files: pydantic models that validate a YAML file, and its SI-unit resolution.

Files carry dB and dBm where engineers expect them; `load_scenario` validates once and returns a
frozen `Scenario` in SI units (W, Hz, m, s, linear ratios) under the paper's symbols. Every choice
the paper leaves open is a field whose description points at docs/model.md.
"""

from __future__ import annotations

import hashlib
import math
import os
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Literal

import numpy as np
import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator

from isac_mission.errors import ConfigError
from isac_mission.types import FloatArray

SPEED_OF_LIGHT_MPS = 299_792_458.0


def db_to_linear(db: float) -> float:
    """10^(dB/10)."""
    return float(10.0 ** (db / 10.0))


def dbm_to_w(dbm: float) -> float:
    """Power in dBm to watts."""
    return db_to_linear(dbm) * 1e-3


class _Section(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid")


class TimingConfig(_Section):
    duration_s: float = Field(60.0, gt=0, description="T, mission duration.")
    slot_s: float = Field(1.0, gt=0, description="Delta t, slot length.")


class AreaConfig(_Section):
    size_m: tuple[float, float] = Field(
        (3000.0, 3000.0), description="Width (x, east) and height (y, north) of the area."
    )

    @model_validator(mode="after")
    def _positive(self) -> AreaConfig:
        if min(self.size_m) <= 0:
            raise ValueError(f"size_m: both sides must be > 0 (got {list(self.size_m)})")
        return self


class RadioConfig(_Section):
    bandwidth_hz: float = Field(20e6, gt=0, description="B, total bandwidth shared by FDMA.")
    carrier_hz: float = Field(28e9, gt=0, description="f_c, carrier frequency.")
    uav_tx_power_dbm: float = Field(20.0, description="P_t^u (0.1 W = 20 dBm).")
    bs_tx_power_dbm: float = Field(30.0, description="P_t^BS (1 W = 30 dBm).")
    noise_power_dbm: float = Field(
        -130.0, description="sigma_0^2, noise power over the whole band B (docs/model.md)."
    )
    ref_gain_db: float | None = Field(
        None,
        description="beta_0, channel gain at 1 m; null = free space (lambda/4pi)^2 (docs/model.md).",
    )
    rate_min_bps: float = Field(10e6, gt=0, description="R_th, minimum rate per UAV.")
    control_snr_min_db: float = Field(11.0, description="Gamma_th, control-link SNR threshold.")
    bs_capacity: int = Field(3, ge=1, description="N_a, UAVs one BS can serve.")


class BaseStationConfig(_Section):
    count: int = Field(5, ge=1, description="K.")
    height_m: float = Field(15.0, ge=0, description="H^B.")
    placement_seed: int = Field(
        2025, ge=0, description="Seed of the uniform random BS layout (docs/model.md)."
    )
    xy_m: list[tuple[float, float]] | None = Field(
        None, description="Explicit BS positions; overrides the random layout."
    )

    @model_validator(mode="after")
    def _count_matches(self) -> BaseStationConfig:
        if self.xy_m is not None and len(self.xy_m) != self.count:
            raise ValueError(f"xy_m: has {len(self.xy_m)} positions but count is {self.count}")
        return self


class UavConfig(_Section):
    altitude_m: float = Field(100.0, gt=0, description="H, flight altitude of UAVs and target.")
    start_xy_m: list[tuple[float, float]] = Field(
        default_factory=lambda: [(1500.0, 2300.0), (807.0, 1100.0), (2193.0, 1100.0)],
        min_length=1,
        description="q_{m,0}; M is its length.",
    )
    max_speed_mps: float = Field(25.0, gt=0, description="V_max.")
    safe_distance_m: float = Field(30.0, ge=0, description="D_s.")
    max_accel_mps2: float = Field(
        10.0,
        gt=0,
        description="Horizontal acceleration limit of the simulated vehicles (not in the paper's "
        "model, which has none; docs/model.md, 'Live service').",
    )


class TargetConfig(_Section):
    initial_state: tuple[float, float, float, float] = Field(
        (600.0, 1600.0, 30.0, 0.0), description="x_0 = [x, y, vx, vy] in m and m/s."
    )
    process_noise_intensity: float = Field(0.5, ge=0, description="kappa in W (eq. 4), m^2/s^3.")
    rcs_dbsm: float = Field(-10.0, description="sigma_RCS.")


class SensingConfig(_Section):
    model: Literal["radar_crb", "literal"] = Field(
        "radar_crb",
        description="radar_crb: alpha_d, alpha_v from the matched-filter CRB; literal: as printed.",
    )
    cpi_s: float = Field(
        0.01, gt=0, description="T^s, coherent processing interval (docs/model.md)."
    )
    alpha_d: float | None = Field(None, gt=0, description="literal model only.")
    alpha_v: float | None = Field(None, gt=0, description="literal model only.")
    missed_detection_prob: float = Field(0.0, ge=0, lt=1)

    @model_validator(mode="after")
    def _alphas_match_model(self) -> SensingConfig:
        given = self.alpha_d is not None or self.alpha_v is not None
        if self.model == "literal" and (self.alpha_d is None or self.alpha_v is None):
            raise ValueError("model literal needs both alpha_d and alpha_v")
        if self.model == "radar_crb" and given:
            raise ValueError(
                "alpha_d/alpha_v are derived by model radar_crb; remove them or use model: literal"
            )
        return self


class TrackerConfig(_Section):
    initial_position_std_m: float = Field(
        10.0, gt=0, description="Std of the tracker's initial position error (P0)."
    )
    initial_velocity_std_mps: float = Field(
        2.0, gt=0, description="Std of the tracker's initial velocity error (P0)."
    )
    update_iterations: int = Field(
        1,
        ge=1,
        le=50,
        description="1: the EKF of the paper; > 1: iterated EKF (relinearised updates, docs/model.md).",
    )
    bound_prior: Literal["pcrb", "ekf"] = Field(
        "pcrb",
        description="Prior information of the planner's bound: its own recursion, or the EKF's P.",
    )


class PlannerConfig(_Section):
    association: Literal["resolve", "keep"] = Field(
        "resolve",
        description="resolve: P1-F.1 from q_{n-1} each slot; keep: Lemma 2 (docs/model.md).",
    )
    epsilon: float = Field(1e-3, gt=0, lt=1, description="Relative-decrease stop (Alg. 1, 2).")
    line_search_step: float = Field(0.05, gt=0, le=1, description="Delta omega of the line search.")
    max_ao_iterations: int = Field(8, ge=1)
    max_position_iterations: int = Field(8, ge=1)
    max_bandwidth_iterations: int = Field(8, ge=1)
    per_uav_steps: bool = Field(
        True,
        description="Line-search each UAV's own step after Algorithm 1's common one (docs/model.md).",
    )
    accel_limit_mps2: float | None = Field(
        None,
        gt=0,
        description="If set, each waypoint stays within a dt^2 / 4 of the vehicle's ballistic "
        "point q + v dt (reachable on a smooth leg); null = the paper's kinematics (docs/model.md).",
    )
    keep_in_area: bool = Field(
        True,
        description="Keep every waypoint inside the operating area (the vehicles' geofence; "
        "not in the paper, docs/model.md).",
    )
    solver: str = Field("CLARABEL", description="cvxpy solver for the SOCP subproblems.")
    feasibility_tol_m: float = Field(
        1e-6, gt=0, description="Slack allowed when re-checking 14a-14j on a returned plan."
    )


DEFAULT_SIGNING_KEY_ENV = "ISAC_MAVLINK_SIGNING_KEY"
"""The environment variable that holds the MAVLink signing key unless the config names another."""
SIGNING_KEY_BYTES = 32
MIN_PASSPHRASE_CHARS = 8


class MavlinkSigningConfig(_Section):
    """MAVLink 2 message signing between the vehicles and the service (docs/reliability.md).

    The file names where the key is, never the key itself: `key_file` if given, otherwise the
    environment variable `key_env`. The key text (surrounding whitespace stripped) is either
    64 hex digits, the 32-byte secret itself (`key_format: hex`), or a passphrase whose SHA-256
    is the secret (`key_format: passphrase`, as MAVProxy's `signing setup` derives it).
    """

    enabled: bool = Field(
        False, description="Sign every outgoing message; reject unsigned or badly signed ones."
    )
    key_file: Path | None = Field(
        None,
        description="File holding the key text (relative: from the working directory); "
        "takes precedence over key_env.",
    )
    key_env: str = Field(
        DEFAULT_SIGNING_KEY_ENV,
        pattern=r"^[A-Za-z_][A-Za-z0-9_]*$",
        description="Environment variable holding the key text, read when key_file is not set.",
    )
    key_format: Literal["hex", "passphrase"] = Field(
        "hex", description="hex: 64 hex digits; passphrase: secret = SHA-256(UTF-8 text)."
    )
    link_id: int = Field(0, ge=0, le=255, description="MAVLink link id in our signatures.")


@dataclass(frozen=True, repr=False)
class MavlinkSigningKey:
    """A resolved MAVLink signing key. Its repr and `fingerprint` never show the secret.

    Attributes:
        secret: The 32-byte secret key.
        link_id: Link id written into our signatures.
        source: Where the key came from ("environment variable X", "file P"), for logs.
    """

    secret: bytes
    link_id: int = 0
    source: str = ""

    def __post_init__(self) -> None:
        if len(self.secret) != SIGNING_KEY_BYTES:
            raise ValueError(f"a signing key has {SIGNING_KEY_BYTES} bytes, got {len(self.secret)}")
        if not 0 <= self.link_id <= 255:
            raise ValueError(f"link_id must be in [0, 255], got {self.link_id}")

    @property
    def fingerprint(self) -> str:
        """8 hex digits of SHA-256 over a label and the secret: tells keys apart in logs."""
        return hashlib.sha256(b"isac-mavlink-key-fingerprint:" + self.secret).hexdigest()[:8]

    def __repr__(self) -> str:
        return (
            f"MavlinkSigningKey(fingerprint={self.fingerprint}, link_id={self.link_id}, "
            f"source={self.source!r})"
        )


def _signing_key_text(cfg: MavlinkSigningConfig, where: str) -> tuple[str, str, str]:
    """(key text, its source for logs, the field to blame) from the file or the environment."""
    if cfg.key_file is not None:
        field_name = f"{where}.key_file"
        try:
            text = cfg.key_file.read_text(encoding="utf-8")
        except OSError as err:
            raise ConfigError(f"{field_name}: cannot read {cfg.key_file}: {err.strerror}") from None
        except UnicodeDecodeError:
            raise ConfigError(f"{field_name}: {cfg.key_file} is not UTF-8 text") from None
        return text.strip(), f"file {cfg.key_file}", field_name
    field_name = f"{where}.key_env"
    text = os.environ.get(cfg.key_env, "").strip()
    if not text:
        raise ConfigError(
            f"{field_name}: signing is enabled but the environment variable {cfg.key_env} "
            "is not set or empty (and no key_file is given)"
        )
    return text, f"environment variable {cfg.key_env}", field_name


def _secret_from_text(text: str, key_format: str, field_name: str) -> bytes:
    """The 32-byte secret of a key text; ConfigError naming the field (never the key)."""
    if not text:
        raise ConfigError(f"{field_name}: the key is empty")
    if key_format == "passphrase":
        if len(text) < MIN_PASSPHRASE_CHARS:
            raise ConfigError(
                f"{field_name}: a passphrase needs at least {MIN_PASSPHRASE_CHARS} characters "
                f"(got {len(text)})"
            )
        return hashlib.sha256(text.encode("utf-8")).digest()
    if len(text) != 2 * SIGNING_KEY_BYTES:
        raise ConfigError(
            f"{field_name}: a hex key has {2 * SIGNING_KEY_BYTES} hex digits "
            f"({SIGNING_KEY_BYTES} bytes), got {len(text)} characters"
        )
    try:
        secret = bytes.fromhex(text)
    except ValueError:
        raise ConfigError(f"{field_name}: the key has characters that are not hex digits") from None
    if not any(secret):
        raise ConfigError(f"{field_name}: an all-zero key is not a key (it disables signing)")
    return secret


def mavlink_signing_key(
    cfg: MavlinkSigningConfig, where: str = "security.mavlink_signing"
) -> MavlinkSigningKey | None:
    """The signing key `cfg` points at, or None when signing is off.

    Raises ConfigError naming the field (`where`.key_file or `where`.key_env) when the key is
    missing, unreadable or malformed; the message never contains the key.
    """
    if not cfg.enabled:
        return None
    text, source, field_name = _signing_key_text(cfg, where)
    secret = _secret_from_text(text, cfg.key_format, field_name)
    return MavlinkSigningKey(secret=secret, link_id=cfg.link_id, source=source)


ZenohTopic = Literal[
    "plan", "track", "health", "clock", "truth", "detections", "telemetry", "control"
]
"""The key expressions of DESIGN.md ("Zenoh") by name: `isac/<mission>/<topic>[/<m>]`."""
_NAME_PATTERN = r"^[A-Za-z0-9_.-]+$"
_ENV_PATTERN = r"^[A-Za-z_][A-Za-z0-9_]*$"


class ZenohRoleConfig(_Section):
    """One role of the Zenoh access control: who holds it and what they may publish."""

    users: list[str] = Field(
        min_length=1, description="Usernames (of the users file) that hold this role."
    )
    publishes: list[ZenohTopic] = Field(
        default_factory=list,
        description="Topics this role may put on (every role may subscribe); [] = read only.",
    )

    @model_validator(mode="after")
    def _names(self) -> ZenohRoleConfig:
        import re

        for user in self.users:
            if not re.match(_NAME_PATTERN, user):
                raise ValueError(f"users: {user!r} must use letters, digits, '_', '.' or '-'")
        return self


def _default_roles() -> dict[str, ZenohRoleConfig]:
    return {
        "ground": ZenohRoleConfig(
            users=["ground"], publishes=["plan", "track", "health", "telemetry"]
        ),
        "world": ZenohRoleConfig(
            users=["world"], publishes=["clock", "truth", "detections", "telemetry"]
        ),
        "operator": ZenohRoleConfig(users=["operator"], publishes=["control"]),
        "observer": ZenohRoleConfig(users=["observer"], publishes=[]),
    }


class ZenohTlsConfig(_Section):
    """TLS on the Zenoh links (endpoints `tls/127.0.0.1:PORT`); `isac-mission gen-certs DIR`
    writes a local CA and a certificate for 127.0.0.1 and localhost."""

    ca_file: Path = Field(description="CA certificate (PEM) the connecting side trusts.")
    cert_file: Path | None = Field(
        None, description="The listening side's certificate (PEM), signed by ca_file."
    )
    key_file: Path | None = Field(None, description="The private key of cert_file (PEM).")

    @model_validator(mode="after")
    def _pair(self) -> ZenohTlsConfig:
        if (self.cert_file is None) != (self.key_file is None):
            raise ValueError("cert_file and key_file go together (set both or neither)")
        return self


class ZenohSecurityConfig(_Section):
    """Zenoh user/password authentication, role-based access control and TLS (README,
    "Security"; docs/reliability.md). Files only: no password is ever written in the scenario.

    The listening side (the ground loop) checks logins against `users_file` and lets each role
    put only on its `publishes` topics; a connecting process logs in with the credentials of
    `user_env` / `password_env`, else `credentials_file`, else its role's first user in
    `users_file`. Relative paths are relative to the working directory.
    """

    enabled: bool = Field(False, description="Turn on user/password auth and the ACL (and TLS).")
    users_file: Path | None = Field(
        None,
        description="`user:password` lines (zenoh's dictionary_file) the listening side checks; "
        "`isac-mission gen-users FILE` writes one with random passwords.",
    )
    credentials_file: Path | None = Field(
        None, description="This process's own login: one `user:password` line."
    )
    user_env: str = Field(
        "ISAC_ZENOH_USER", pattern=_ENV_PATTERN, description="Env variable: this process's user."
    )
    password_env: str = Field(
        "ISAC_ZENOH_PASSWORD",
        pattern=_ENV_PATTERN,
        description="Env variable: this process's password.",
    )
    roles: dict[str, ZenohRoleConfig] = Field(
        default_factory=_default_roles,
        description="Role name -> users and the topics they may publish; needs ground and world.",
    )
    tls: ZenohTlsConfig | None = Field(None, description="TLS on every Zenoh link (null: tcp).")

    @model_validator(mode="after")
    def _roles(self) -> ZenohSecurityConfig:
        import re

        for name in self.roles:
            if not re.match(_NAME_PATTERN, name):
                raise ValueError(f"roles: name {name!r} must use letters, digits, '_', '.' or '-'")
        missing = [r for r in ("ground", "world") if r not in self.roles]
        if missing:
            raise ValueError(f"roles: needs a {' and a '.join(missing)} role (the processes' own)")
        seen: dict[str, str] = {}
        for name, role in self.roles.items():
            for user in role.users:
                if user in seen:
                    raise ValueError(f"roles: user {user!r} is in both {seen[user]} and {name}")
                seen[user] = name
        return self


class SecurityConfig(_Section):
    """Who may command the vehicles and publish on the bus. Off by default (loopback only)."""

    mavlink_signing: MavlinkSigningConfig = MavlinkSigningConfig()
    zenoh: ZenohSecurityConfig = ZenohSecurityConfig()


class ScenarioFile(_Section):
    """The YAML file as written (dB units). See config/paper.yaml for every key."""

    mission_id: str = Field("paper", pattern=r"^[A-Za-z0-9_-]+$")
    seed: int = Field(1, ge=0, description="Base seed of the Monte Carlo runs.")
    timing: TimingConfig = TimingConfig()
    area: AreaConfig = AreaConfig()
    radio: RadioConfig = RadioConfig()
    base_stations: BaseStationConfig = BaseStationConfig()
    uavs: UavConfig = UavConfig()
    target: TargetConfig = TargetConfig()
    sensing: SensingConfig = SensingConfig()
    tracker: TrackerConfig = TrackerConfig()
    planner: PlannerConfig = PlannerConfig()
    security: SecurityConfig = SecurityConfig()


@dataclass(frozen=True)
class Scenario:
    """A resolved scenario in SI units, named after the paper's symbols.

    Arrays: bs_xy [K, 2], uav_start_xy [M, 2], x0 [4], P0 [4, 4], area [2].
    """

    mission_id: str
    seed: int
    M: int
    K: int
    N: int
    dt: float
    area: FloatArray
    B: float
    fc: float
    wavelength: float
    Pu: float
    P_bs: float
    noise_w: float
    beta0: float
    rho0: float
    r_th: float
    gamma_th: float
    n_a: int
    d_th: float
    H: float
    H_bs: float
    dH: float
    bs_xy: FloatArray
    uav_start_xy: FloatArray
    v_max: float
    d_safe: float
    a_max: float
    x0: FloatArray
    kappa: float
    rcs_m2: float
    sensing_model: str
    Ts: float
    alpha_d: float
    alpha_v: float
    missed_detection_prob: float
    P0: FloatArray
    bound_prior: str
    ekf_iterations: int
    planner: PlannerConfig = field(default_factory=PlannerConfig)
    security: SecurityConfig = field(default_factory=SecurityConfig)
    mavlink_signing_key: MavlinkSigningKey | None = None
    """Resolved from security.mavlink_signing; None when signing is off. Never traced."""

    @property
    def radar_gain(self) -> float:
        """c0 in SNR^s = c0 / d^4 [m^4]: lambda^2 Pu sigma_RCS / ((4 pi)^3 sigma_0^2)."""
        return self.wavelength**2 * self.Pu * self.rcs_m2 / ((4 * math.pi) ** 3 * self.noise_w)

    def with_changes(self, **changes: Any) -> Scenario:
        """A copy with some fields replaced (no re-validation: for studies and tests)."""
        return replace(self, **changes)

    def trace_config(self) -> dict[str, Any]:
        """Every resolved parameter under the trace's names (DESIGN.md), JSON-ready."""
        return {
            "mission_id": self.mission_id,
            "M": self.M,
            "K": self.K,
            "N": self.N,
            "dt": self.dt,
            "area": self.area.tolist(),
            "B": self.B,
            "fc": self.fc,
            "Pu": self.Pu,
            "P_bs": self.P_bs,
            "noise_w": self.noise_w,
            "rcs_m2": self.rcs_m2,
            "H": self.H,
            "H_bs": self.H_bs,
            "alpha_d": self.alpha_d,
            "alpha_v": self.alpha_v,
            "Ts": self.Ts,
            "kappa": self.kappa,
            "v_max": self.v_max,
            "d_safe": self.d_safe,
            "a_max": self.a_max,
            "gamma_th": self.gamma_th,
            "r_th": self.r_th,
            "n_a": self.n_a,
            "beta0": self.beta0,
            "rho0": self.rho0,
            "d_th": self.d_th,
            "bs_xy": self.bs_xy.tolist(),
            "uav_start_xy": self.uav_start_xy.tolist(),
            "x0": self.x0.tolist(),
            "P0": self.P0.tolist(),
            "sensing_model": self.sensing_model,
            "missed_detection_prob": self.missed_detection_prob,
            "bound_prior": self.bound_prior,
            "ekf_iterations": self.ekf_iterations,
            "planner": self.planner.model_dump(),
        }


def radar_crb_alphas(bandwidth_hz: float, wavelength_m: float, cpi_s: float) -> tuple[float, float]:
    """alpha_d [m^2 Hz^2] and alpha_v [m^2/s^2 s^2] of eq. 8 from the matched-filter CRB.

    With noise PSD N0 = sigma_0^2 / B, the echo energy-to-noise ratio over the CPI is
    SNR^s B T^s whatever the share eta; a flat spectrum of width eta B has rms bandwidth
    eta B / sqrt(12) and a constant envelope of length T^s has rms duration T^s / sqrt(12).
    The delay and Doppler CRBs then give (docs/model.md, "Sensing noise"):
      sigma_d^2 = 3 c^2 / (8 pi^2 B T^s) / (SNR^s (eta B)^2)
      sigma_v^2 = 3 lambda^2 / (8 pi^2 B T^s) / (SNR^s (T^s)^2).
    """
    scale = 3.0 / (8.0 * math.pi**2 * bandwidth_hz * cpi_s)
    return scale * SPEED_OF_LIGHT_MPS**2, scale * wavelength_m**2


def random_bs_layout(count: int, area_m: FloatArray, seed: int) -> FloatArray:
    """[K, 2] BS positions drawn uniformly in the area with a fixed seed."""
    rng = np.random.default_rng(seed)
    return rng.uniform(0.0, 1.0, size=(count, 2)) * area_m


def resolve(spec: ScenarioFile) -> Scenario:
    """Convert a validated file to SI units and derive the paper's constants.

    Raises ConfigError for cross-field problems (UAVs closer than D_s, out of control range, ...).
    """
    radio, bs, uav, tgt, sens = spec.radio, spec.base_stations, spec.uavs, spec.target, spec.sensing
    wavelength = SPEED_OF_LIGHT_MPS / radio.carrier_hz
    beta0 = (
        db_to_linear(radio.ref_gain_db)
        if radio.ref_gain_db is not None
        else (wavelength / (4 * math.pi)) ** 2
    )
    Pu, P_bs, noise_w = (
        dbm_to_w(radio.uav_tx_power_dbm),
        dbm_to_w(radio.bs_tx_power_dbm),
        dbm_to_w(radio.noise_power_dbm),
    )
    gamma_th = db_to_linear(radio.control_snr_min_db)
    dH = uav.altitude_m - bs.height_m
    area = np.asarray(spec.area.size_m, dtype=float)
    bs_xy = (
        np.asarray(bs.xy_m, dtype=float)
        if bs.xy_m is not None
        else random_bs_layout(bs.count, area, bs.placement_seed)
    )
    d_th_sq = P_bs * beta0 / (noise_w * gamma_th) - dH**2
    if sens.model == "radar_crb":
        alpha_d, alpha_v = radar_crb_alphas(radio.bandwidth_hz, wavelength, sens.cpi_s)
    else:
        assert sens.alpha_d is not None and sens.alpha_v is not None
        alpha_d, alpha_v = sens.alpha_d, sens.alpha_v
    sp, sv = spec.tracker.initial_position_std_m, spec.tracker.initial_velocity_std_mps
    n_slots = spec.timing.duration_s / spec.timing.slot_s
    scenario = Scenario(
        mission_id=spec.mission_id,
        seed=spec.seed,
        M=len(uav.start_xy_m),
        K=bs.count,
        N=round(n_slots),
        dt=spec.timing.slot_s,
        area=area,
        B=radio.bandwidth_hz,
        fc=radio.carrier_hz,
        wavelength=wavelength,
        Pu=Pu,
        P_bs=P_bs,
        noise_w=noise_w,
        beta0=beta0,
        rho0=Pu * beta0 / noise_w,
        r_th=radio.rate_min_bps,
        gamma_th=gamma_th,
        n_a=radio.bs_capacity,
        d_th=math.sqrt(d_th_sq) if d_th_sq > 0 else 0.0,
        H=uav.altitude_m,
        H_bs=bs.height_m,
        dH=dH,
        bs_xy=bs_xy,
        uav_start_xy=np.asarray(uav.start_xy_m, dtype=float),
        v_max=uav.max_speed_mps,
        d_safe=uav.safe_distance_m,
        a_max=uav.max_accel_mps2,
        x0=np.asarray(tgt.initial_state, dtype=float),
        kappa=tgt.process_noise_intensity,
        rcs_m2=db_to_linear(tgt.rcs_dbsm),
        sensing_model=sens.model,
        Ts=sens.cpi_s,
        alpha_d=alpha_d,
        alpha_v=alpha_v,
        missed_detection_prob=sens.missed_detection_prob,
        P0=np.diag([sp**2, sp**2, sv**2, sv**2]),
        bound_prior=spec.tracker.bound_prior,
        ekf_iterations=spec.tracker.update_iterations,
        planner=spec.planner,
        security=spec.security,
        mavlink_signing_key=mavlink_signing_key(spec.security.mavlink_signing),
    )
    problems = _cross_field_problems(scenario, n_slots)
    if problems:
        raise ConfigError("\n".join(problems))
    return scenario


def _cross_field_problems(s: Scenario, n_slots: float) -> list[str]:
    """Feasibility checks that involve several sections; one message per problem."""
    out: list[str] = []
    if abs(n_slots - round(n_slots)) > 1e-9:
        out.append(f"timing: duration_s / slot_s must be a whole number of slots (got {n_slots})")
    if s.M > s.K * s.n_a:
        out.append(
            f"uavs.start_xy_m: {s.M} UAVs cannot be served by {s.K} BSs of capacity {s.n_a} "
            f"(M > K * N_a)"
        )
    if s.d_th <= 0:
        out.append(
            "radio: control link never closes: P_bs beta0 / (sigma0^2 Gamma_th) <= (H - H^B)^2 "
            f"(d_th^2 = {s.P_bs * s.beta0 / (s.noise_w * s.gamma_th) - s.dH**2:.3g} m^2)"
        )
    for m, q in enumerate(s.uav_start_xy):
        if not (0 <= q[0] <= s.area[0] and 0 <= q[1] <= s.area[1]):
            out.append(f"uavs.start_xy_m[{m}]: {q.tolist()} is outside the area {s.area.tolist()}")
        nearest = float(np.min(np.linalg.norm(s.bs_xy - q, axis=1)))
        if s.d_th > 0 and nearest > s.d_th:
            out.append(
                f"uavs.start_xy_m[{m}]: {q.tolist()} is {nearest:.0f} m from the nearest BS, "
                f"beyond the control range d_th = {s.d_th:.0f} m"
            )
    for i in range(s.M):
        for j in range(i + 1, s.M):
            gap = float(np.linalg.norm(s.uav_start_xy[i] - s.uav_start_xy[j]))
            if gap < s.d_safe:
                out.append(
                    f"uavs.start_xy_m[{i}], [{j}]: {gap:.1f} m apart, closer than "
                    f"safe_distance_m = {s.d_safe} m"
                )
    p = s.x0[:2]
    if not (0 <= p[0] <= s.area[0] and 0 <= p[1] <= s.area[1]):
        out.append(f"target.initial_state: position {p.tolist()} is outside the area")
    for m, q in enumerate(s.uav_start_xy):
        gap = float(np.linalg.norm(q - p))
        if gap < s.d_safe:
            out.append(
                f"uavs.start_xy_m[{m}]: {gap:.1f} m from the target's start, closer than "
                f"safe_distance_m = {s.d_safe} m"
            )
    return out


def _format_validation_error(source: str, err: ValidationError) -> str:
    lines = []
    for e in err.errors():
        where = ".".join(str(p) for p in e["loc"]) or "(top level)"
        msg = e["msg"]
        if e["type"] == "extra_forbidden":
            msg = "unknown key"
        elif msg.startswith("Value error, "):
            msg = msg[len("Value error, ") :]
        got = e.get("input")
        secret = e["loc"][:1] == ("security",)  # never echo what might be a key or password
        got_txt = "" if isinstance(got, dict) or secret else f" (got {got!r})"
        lines.append(f"{source}: {where}: {msg}{got_txt}")
    return "\n".join(lines)


def parse_scenario(data: Any, source: str = "<config>") -> Scenario:
    """Validate a mapping (as read from YAML) and resolve it. Raises ConfigError."""
    if not isinstance(data, dict):
        raise ConfigError(
            f"{source}: the file must hold a mapping of sections, got {type(data).__name__}"
        )
    try:
        spec = ScenarioFile.model_validate(data)
    except ValidationError as err:
        raise ConfigError(_format_validation_error(source, err)) from None
    try:
        return resolve(spec)
    except ConfigError as err:
        raise ConfigError(
            "\n".join(f"{source}: {line}" for line in str(err).splitlines())
        ) from None


def load_scenario(path: str | Path) -> Scenario:
    """Read, validate and resolve a YAML scenario file. Raises ConfigError, never a traceback."""
    p = Path(path)
    try:
        text = p.read_text()
    except OSError as err:
        raise ConfigError(f"{p}: cannot read: {err.strerror}") from None
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as err:
        raise ConfigError(f"{p}: not valid YAML: {err}") from None
    return parse_scenario(data, str(p))
