"""Geometric controller settings (mission key ``control``).

Owned by the control module (issue 4). Units: N, m, s, rad, gauss.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal


@dataclass(frozen=True)
class ControlConfig:
    """Gains and sensor settings of the paper's Section 2.4.2 controller.

    Attributes
    ----------
    kx : float
        Position gain k_x of eq. (23), N/m.
    kv : float
        Velocity gain k_v of eq. (23), N s/m. With m = 4.34 kg the defaults
        (60, 30) give translational poles ``s^2 + 6.9 s + 13.8``: 3.7 rad/s,
        damping 0.93. A tilt error theta moves the vehicle by about ``m g
        theta / kx`` at low frequency, so kx is what rejects the attitude
        noise that the measurement noise leaves (Lee et al.'s 16 / 5.6 gives
        3-4x the position error at the paper's noise level).
    rho1 : float
        Weight rho_1 of the specific-force vector in z_rho (eq. 28), 1/s^2.
        Since the torque is J z_rho, z_rho is an angular acceleration: for a
        small error the attitude loop is ``theta_ddot + alpha theta_dot +
        W_rho theta = 0`` with ``W_rho = sum rho_i (I - r_i r_i^T)``. rho1 sets
        the roll/pitch stiffness: 200 gives 14 rad/s, ~4x the position loop.
    rho2 : float
        Weight rho_2 of the magnetic vector in eq. (28), 1/s^2, with
        ``attitude_law: paper`` (the yaw stiffness there, with
        ``mag_perpendicular``; 0.2 rho2 with the raw field). The default
        decoupled law derives its yaw stiffness instead (``yaw_*`` below).
    alpha : float
        Angular-velocity damping alpha of eqs. (27) and (35), 1/s: roll and
        pitch (all three axes with ``attitude_law: paper``). 12 damps the tilt
        at ~0.4 (``alpha / (2 sqrt(rho1))``).
    yaw_rate_cutoff_hz : float
        Corner (Hz) of the first-order low-pass on the yaw rate that the
        decoupled law's yaw damping acts on (``companion.control.yaw``; PX4
        ``MC_YAW_TQ_CUTOFF`` 2 Hz and ArduCopter ``ATC_RAT_YAW_FLTE`` 2.5 Hz
        filter yaw for the same reason), > 0.
    yaw_noise_fraction : float
        The decoupled law's yaw damping is ``alpha_y = yaw_noise_fraction x
        a_yaw / sigma_f``: the gyro noise left after the low-pass (sigma_f,
        from ``gyro_noise_rad_s_sqrt_hz``) asks for this fraction of the yaw
        acceleration the rotors can make at hover (a_yaw, 0.247 rad/s^2 on the
        paper's vehicle) at 1 sigma; bounded by alpha. In (0, 1); 0.1 gives
        alpha_y = 4.46 /s.
    yaw_damping_ratio : float
        Damping ratio zeta of the yaw loop: its stiffness is ``rho_y =
        (alpha_y / (2 zeta))^2`` (7.77 /s^2, 2.79 rad/s with 0.8), > 0.
    mag_field_enu_gauss : tuple (3,)
        The Earth field in the world ENU frame: the known inertial direction
        of the magnetometer vector. Default: the bundled SITL's default
        (``sim.magnetic_field_enu_gauss``, about Bordeaux's); set it to the
        local field (e.g. from a world magnetic model) on a real vehicle.
    accel_filter_tau_s : float
        Time constant (s) of the low-pass on the differentiated velocity that
        gives the vehicle acceleration, hence the world direction of the
        specific force. 0: raw backward difference (noise-free velocity).
    accel_vector_gain_rad_s : float
        Low-pass gain (1/s) on the measured specific-force direction in the
        body frame, which is constant (e3) for a drag-free multirotor: its
        noise is pure noise, and the position error follows its low-frequency
        part, so the gain is low (0.05: 20 s). With aerodynamic drag D the
        true direction is ``unit(f e3 + R^T D)``; the part of it the filter
        has not followed makes the TRIAD estimate put the thrust axis along
        the total specific force ``(f R e3 + D)/m`` (``r_1``, from the
        velocity), so the attitude loop steers the total non-gravity force,
        drag included, onto b3d: the drag changes faster than 1/gain are
        rejected like an acceleration feedback, the slower part (which the
        filter follows) is a force disturbance for the integral term.
        A faster gain is therefore worse under drag, not better (windy
        flat-rectangle, ki = 0: gain 1.0 -> 20.1 mm max, 0.2 -> 16.2 mm,
        0.02 -> 14.4 mm). 0: unfiltered (the paper).
    mag_vector_gain_rad_s : float
        Correction gain (1/s) of the gyro-propagated complementary filter on
        the measured magnetic-field direction. It mainly quiets the yaw
        torque. 0: unfiltered (the paper).
    mag_perpendicular : bool
        Use the field's component normal to the specific force as the second
        vector (decouples yaw from tilt; ``companion.control.vectors``).
        False: the raw field, as the paper.

    ki : float
        Integral gain k_i (N/(m s)) on the position error, the term ``-k_i
        e_i`` added to eq. (23) (``companion.control.geometric`` docstring):
        it removes the steady error ``F/kx`` that a constant disturbance
        force F (wind drag) leaves. The closed loop ``m s^3 + kv s^2 + kx s +
        ki`` is stable for ``ki < kv kx / m`` (Routh: 415); 60 puts its slow
        pair at -1.19 +- 1.28j (damping 0.68) and keeps 7x margin. 0: off
        (the paper's law).
    integral_limit_fraction : float
        Anti-windup bound: ``|k_i e_i| <= integral_limit_fraction m g`` (the
        integral is projected back onto that ball), in (0, 1).
    integral_zone_m : float
        Conditional integration: the integral only accumulates while
        ``|e_x|`` is below this (m), so that the large errors of the take-off
        (the vehicle on the ground while the reference climbs) or of a
        hand-over do not wind it up. It must exceed the largest steady error
        the bound can cancel, ``integral_limit_fraction m g / kx`` (71 mm
        with the defaults), or a strong steady wind would never be
        integrated. The runner may also call ``GeometricController.reset()``.

    tilt_max_deg : float
        Safety limit: the largest tilt of the desired thrust direction b3d
        from vertical (deg), in (0, 90); PX4's ``MPC_TILTMAX_AIR`` (default 45).
        F_d of eq. (23) is limited to this cone before it is normalised
        (``companion.control.tilt``): the controller never asks for a flip.
        Inactive in ordinary flight (a few degrees); only large errors (a
        hand-over during a fast climb) reach it.
    vertical_thrust_min_fraction : float
        Floor of the vertical component of F_d as a fraction of m g, in
        (0, 1) (PX4's ``MPC_THR_MIN`` idea): at most ``(1 - fraction) g`` of
        commanded downward acceleration, and never a thrust vector pointing down.

    attitude_law : str
        "decoupled" (default): the thrust direction is controlled in the body
        frame independently of the yaw error
        (``geometric.attitude_torque_decoupled``), so a yaw that lags or
        saturates on this weak-yaw vehicle cannot disturb the position.
        "paper": eq. (27) as printed (signs restored), the coupled law.
    pointing_limit : bool
        Fly a yaw-rate/yaw-acceleration limited version of eq. (21)'s
        pointing (``companion.control.pointing``), exact eq. (21) wherever it
        is within the limits below. False: eq. (21) as is.
    pointing_yaw_rate_max_rad_s : float
        Yaw-rate limit of the pointing reference (rad/s).
    pointing_yaw_accel_fraction : float
        Yaw-acceleration limit of the pointing reference as a fraction of the
        vehicle's yaw acceleration at hover (``Mixer.yaw_torque_limit(m g) /
        J_zz``, 0.25 rad/s^2 for the paper's vehicle), in (0, 1]; the rest is
        the margin that rejects disturbances and noise.

    vectors : "physical" or "paper"
        What the vehicle's accelerometer fields carry, as the SITL's
        ``sim.vector_sensors``: "physical" (default) the specific force
        ``R^T (a + g e3)`` of a real IMU; "paper" the paper's sensor model
        (Section 3.4), a unit vector of constant inertial direction ``g R^T
        e3``, so the controller takes ``r1 = e3`` (and ``r2 = m_hat``).
    velocity_aided : bool
        The world direction of the specific force from the velocity fixes
        (``dv/dt + g e3``): without the observer, ``r1 = unit(a_hat + g e3)``
        with ``a_hat`` the differentiated velocity and, with the paper's
        vectors, ``b1 = e3`` (the thrust axis of eq. 20's drag-free plant);
        with the observer, its velocity-aided tilt innovation. False, without
        the observer: ``r1 = e3`` against the accelerometer (the paper's law
        on the paper's vectors; biased under acceleration on a physical IMU).
    observer : bool
        The attitude observer of ``companion.control.observer`` (default):
        the law acts on the virtual pairs ``b_i = R_hat^T r_i`` (``r1 = e3``,
        ``r2`` the horizontal field), the bias-corrected gyro, and the
        position/velocity of its translational filter (current time, between
        and despite late fixes). The vector filters (``*_vector_gain_rad_s``)
        then act inside it only on the accelerometer direction. False: the
        (filtered) measured vectors, the raw position/velocity (the paper).
    observer_tilt_gain_max_rad_s : float
        Cap of the velocity-aided tilt correction rate (1/s); the rate itself
        follows the fix noise (``observer.tilt_gain``): 100 with exact fixes
        every 4 ms, ~1 at 1 cm/s, ~0.4 with 10 Hz RTK fixes.
    observer_gravity_gain_rad_s : float
        Rate (1/s) of the accelerometer-against-e3 innovation, used with the
        paper's vectors or without velocity aiding.
    observer_mag_gain_rad_s : float
        Rate (1/s) of the heading innovation (magnetometer, horizontal part).
    observer_bias_gain_1_s : float
        Gyro-bias integral gain k_b (1/s): ``b_hat_dot = -k_b sigma``;
        bias error decays at about k_b (tilt) and 0.11/s (heading, k_m = 1).
    observer_bias_max_rad_s : float
        Bound of the estimated gyro bias (rad/s).
    observer_window_s : float
        Longest velocity window of the tilt innovation (s), reached at 5
        mm/s of fix noise (one fix interval with exact fixes).
    observer_history_s : float
        History kept for late fixes (s): fix latency + window must fit.
    nav_position_std_m, nav_velocity_std_m_s : float
        Position/velocity fix noise the observer assumes (floors of its
        online estimate with ``nav_adaptive_noise``); 0: exact (mocap).
    nav_accel_noise_m_s2_sqrt_hz : float
        White acceleration noise of the translational filter's input
        (accelerometer noise and model error), m/s^2/sqrt(Hz).
    nav_accel_bias_walk_m_s3_sqrt_hz : float
        Random walk of its acceleration bias state, m/s^3/sqrt(Hz).
    nav_adaptive_noise : bool
        Estimate the fix noise online from the fixes themselves (default):
        one default serves exact 250 Hz mocap fixes and noisy 10 Hz RTK.
    gyro_noise_rad_s_sqrt_hz : float
        Gyro noise density the tilt gain assumes (rad/s/sqrt(Hz)); default
        the paper's variance 5e-4 at 250 Hz (1.4e-3).

    Mission figures (in-process, ``python benchmarks/paper_reproduction.py``
    and ``python benchmarks/noise_sweep.py``: the planned trajectories on the
    SITL's plant, mission seeds, max / RMS error after 5 s): the default on
    the SITL's default sensors (physical IMU, the paper's noise, exact
    position) 0.42 / 0.13 mm on flat-rectangle (0.41 / 0.12 without the
    observer); on the paper's sensors (``vectors: paper``) 0.34 / 0.32 mm
    max on flat-rectangle / tilted-hexagon, where the paper's law gets 21.0
    / 18.7 mm (4.95 / 4.84 with the pointing governor). White velocity
    noise 1 cm/s and 5 cm/s (every frame): 1.43 and 2.32 mm max (the
    previous default, no observer: 1.8 m, diverged). Windy flat-rectangle
    4.9 / 2.0 mm. Over MAVLink ``companion demo`` on the default mission 0.38
    / 0.13 mm; on the paper's sensors 0.33 mm (the paper's law 19.8 mm,
    3.8 mm with the governor). BENCHMARKS.md "Controller on real sensors".

    The previous figures (no observer, tilt from the differentiated exact
    velocity; ``python benchmarks/bench_control.py``, in-process plant,
    250 Hz sample and hold, the paper's noise, 25 s on 1 m/s paths): max
    position error after 5 s about 0.5 mm (0.85 mm with ki = 0), 3.4 mm
    with the vector filters off, 3.5-3.7 mm with Lee et al.'s kx, kv = 16,
    5.6 (and ki = 0: 60 is beyond their Routh bound, 20.6). With wind
    (``flat-rectangle-windy``, ``companion demo``) 5.0 mm max / 2.0 mm RMS
    against 15.9 / 11.2 mm without the integral.
    """

    kx: float = 60.0
    kv: float = 30.0
    rho1: float = 200.0
    rho2: float = 50.0
    alpha: float = 12.0
    yaw_rate_cutoff_hz: float = 5.0
    yaw_noise_fraction: float = 0.1
    yaw_damping_ratio: float = 0.8
    mag_field_enu_gauss: tuple[float, float, float] = (0.0, 0.21, -0.42)
    accel_filter_tau_s: float = 0.0
    accel_vector_gain_rad_s: float = 0.05
    mag_vector_gain_rad_s: float = 1.0
    mag_perpendicular: bool = True
    ki: float = 60.0
    integral_limit_fraction: float = 0.1
    integral_zone_m: float = 0.1
    tilt_max_deg: float = 45.0
    vertical_thrust_min_fraction: float = 0.25
    attitude_law: str = "decoupled"
    pointing_limit: bool = True
    pointing_yaw_rate_max_rad_s: float = 1.0
    pointing_yaw_accel_fraction: float = 0.5
    vectors: Literal["physical", "paper"] = "physical"
    velocity_aided: bool = True
    observer: bool = True
    observer_tilt_gain_max_rad_s: float = 100.0
    observer_gravity_gain_rad_s: float = 0.5
    observer_mag_gain_rad_s: float = 1.0
    observer_bias_gain_1_s: float = 0.1
    observer_bias_max_rad_s: float = 0.2
    observer_window_s: float = 0.3
    observer_history_s: float = 0.6
    nav_position_std_m: float = 0.0
    nav_velocity_std_m_s: float = 0.0
    nav_accel_noise_m_s2_sqrt_hz: float = 0.02
    nav_accel_bias_walk_m_s3_sqrt_hz: float = 0.01
    nav_adaptive_noise: bool = True
    gyro_noise_rad_s_sqrt_hz: float = 1.4e-3

    def __post_init__(self) -> None:
        for name in ("kx", "kv", "rho1", "rho2", "alpha", "yaw_rate_cutoff_hz", "yaw_damping_ratio"):
            if not getattr(self, name) > 0:
                raise ValueError(f"control.{name} must be > 0")
        if not 0 < self.yaw_noise_fraction < 1:
            raise ValueError("control.yaw_noise_fraction must be in (0, 1)")
        for name in ("accel_filter_tau_s", "accel_vector_gain_rad_s", "mag_vector_gain_rad_s"):
            if not getattr(self, name) >= 0:
                raise ValueError(f"control.{name} must be >= 0")
        if not self.ki >= 0:
            raise ValueError("control.ki must be >= 0")
        if not 0 < self.integral_limit_fraction < 1:
            raise ValueError("control.integral_limit_fraction must be in (0, 1)")
        if not self.integral_zone_m > 0:
            raise ValueError("control.integral_zone_m must be > 0")
        if not 0 < self.tilt_max_deg < 90:
            raise ValueError("control.tilt_max_deg must be in (0, 90)")
        if not 0 < self.vertical_thrust_min_fraction < 1:
            raise ValueError("control.vertical_thrust_min_fraction must be in (0, 1)")
        if self.attitude_law not in ("decoupled", "paper"):
            raise ValueError("control.attitude_law must be 'decoupled' or 'paper'")
        if not self.pointing_yaw_rate_max_rad_s > 0:
            raise ValueError("control.pointing_yaw_rate_max_rad_s must be > 0")
        if not 0 < self.pointing_yaw_accel_fraction <= 1:
            raise ValueError("control.pointing_yaw_accel_fraction must be in (0, 1]")
        if not math.hypot(*self.mag_field_enu_gauss) > 0:
            raise ValueError("control.mag_field_enu_gauss must not be zero")
        if self.observer and not math.hypot(*self.mag_field_enu_gauss[:2]) > 0:
            raise ValueError("control.mag_field_enu_gauss must have a horizontal part (the observer's heading)")
        if self.vectors not in ("physical", "paper"):
            raise ValueError("control.vectors must be 'physical' or 'paper'")
        for name in ("observer_tilt_gain_max_rad_s", "observer_history_s", "nav_accel_noise_m_s2_sqrt_hz",
                     "gyro_noise_rad_s_sqrt_hz"):
            if not getattr(self, name) > 0:
                raise ValueError(f"control.{name} must be > 0")
        for name in ("observer_gravity_gain_rad_s", "observer_mag_gain_rad_s", "observer_bias_gain_1_s",
                     "observer_bias_max_rad_s", "observer_window_s", "nav_position_std_m",
                     "nav_velocity_std_m_s", "nav_accel_bias_walk_m_s3_sqrt_hz"):
            if not getattr(self, name) >= 0:
                raise ValueError(f"control.{name} must be >= 0")
        if not self.observer_window_s < self.observer_history_s:
            raise ValueError("control.observer_window_s must be < control.observer_history_s")
        if self.observer and not self.velocity_aided and not self.observer_gravity_gain_rad_s > 0:
            raise ValueError("control.observer without velocity_aided needs observer_gravity_gain_rad_s > 0 "
                             "(no tilt information otherwise)")
