"""What the calls return: small frozen dataclasses of floats and numpy arrays, in the model's units.

Lengths and distances are in the units of the model's error coordinates (metres for ``dubins4d``), speeds
in its parameters' unit (m/s), controls in the controls' units (rad/s and m/s^2 for ``dubins4d``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

Floats = npt.NDArray[np.float64]
Bools = npt.NDArray[np.bool_]


@dataclass(frozen=True)
class PlannerControl:
    """queryPlannerControl's answer: the planner speed bound to use and the bounds that come with it."""

    beta_query: float
    """Planner speed bound (m/s): the largest table beta whose TEB radius is at most d_obs / 2."""
    dteb_radius: float
    """TEB radius at ``beta_query`` (the dTEB), metres."""
    steb_radius: float
    """TEB radius at the slowest beta, beta_l (the sTEB), metres."""
    steb_exceeds_half_distance: bool
    """True if even the sTEB exceeds d_obs / 2: the robot is closer to an obstacle than the slowest plan allows."""
    model_version: int
    """The model version that answered."""


@dataclass(frozen=True)
class TrackingErrorBound:
    """The tracking error bound (TEB) of a planner speed bound."""

    level: float
    """Level of the certified set {r : V(r; beta) <= level} (``TebRow.set_level``): the relative states the
    bound holds from; ``in_teb`` is membership in it."""
    radius: float
    """The tracking error bound (``TebRow.bound``), metres: from inside the certified set the error stays
    within it."""
    extent: Floats
    """Half-widths of the certified set's bounding box along each error coordinate, metres, shape [n_error]."""
    table_beta: float
    """The TEB-table beta that answered (>= the beta asked for), m/s."""
    boundary: Floats
    """Points on the certified set's boundary (error coordinates), shape [boundary_points, n_error], metres."""
    model_version: int
    """The model version that answered."""


@dataclass(frozen=True)
class Evaluation:
    """``EvaluateValue`` of a batch of N relative states."""

    values: Floats
    """V(r; beta) per item, shape [N], metres."""
    gradients: Floats
    """dV/dr per item, shape [N, n_state] (value unit per state unit)."""
    controls: Floats
    """Optimal tracker control u* per item, shape [N, n_control], in the controls' units."""
    in_teb: Bools
    """Per item: r lies in the TEB of its beta, shape [N]."""
    in_domain: Bools
    """Per item: r lies in the trained domain (False: extrapolated, do not trust), shape [N]."""
    model_version: int
    """The model version that answered."""


@dataclass(frozen=True)
class TrackingControl:
    """``TrackingControl`` of a batch of N relative states."""

    controls: Floats
    """Optimal tracker control u* per item, shape [N, n_control], in the controls' units."""
    values: Floats
    """V(r; beta) per item, shape [N], metres."""
    in_teb: Bools
    """Per item: r lies in the TEB of its beta, shape [N]."""
    in_domain: Bools
    """Per item: r lies in the trained domain, shape [N]."""
    model_version: int
    """The model version that answered."""


@dataclass(frozen=True)
class TrackReply:
    """The server's answer to one ``Track`` tick."""

    seq: int
    """The tick's sequence number."""
    beta_query: float
    """Planner speed bound for this step (m/s)."""
    dteb_radius: float
    """TEB radius at ``beta_query``, metres: the tracking error stays within it."""
    steb_radius: float
    """TEB radius at beta_l, metres."""
    relative_state: Floats
    """r = s - Q p, shape [n_state] (periodic coordinates wrapped)."""
    value: float
    """V(r; beta_query), metres."""
    in_teb: bool
    """r lies in the TEB of ``beta_query``."""
    in_domain: bool
    """r lies in the trained domain (False: the control is extrapolated, do not trust it)."""
    control: Floats
    """Optimal tracker control u*, shape [n_control] (dubins4d: turn rate rad/s, acceleration m/s^2)."""
