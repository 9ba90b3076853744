"""Non-classical Coulomb friction in augmented Lagrangian form: return mapping (2.35)-(2.43),
computed per pair by the contact kernel (``evaluate._return_mapping``); the stick/slip codes.

In 2D the tangential traction is a scalar t_T along the pair's tangent e (2.7), so
trial/|trial| is a sign. The trial traction is

    t_T^trial = t_T,n + dLambda_T + eps_T * s,     (2.41)

with s = gdot_T (rate law, 2.10) or s = delta g_T, the tangential relative displacement since the
step start (gap law). The pair slips if phi = |t^trial| - mu t_N > 0 (2.42-2.43), and then
t_T = mu t_N sign(t^trial) (2.39).

Direction-reversal rule (report 3.3.2): a pair whose trial traction would slip AGAINST its
current tangential motion (s * t^trial < 0) has reversed its sliding direction relative to the
traction it carried from the previous step; the report lets it stick for that step
(gdot_T taken as 0). It is flagged STICK, and its traction is kept in the Coulomb cone,
t_T = mu t_N sign(t^trial). With this rule every SLIP pair has t_T * s >= 0, so the
frictional dissipation (3.18) is non-negative by construction. A reversal that overshoots (the
trial already points along the new motion) slips in the new direction and dissipates.

The frictional dissipation of a step is the sum over SLIP pairs of t_T delta g_T L_c
(3.17)-(3.18), delta g_T = gdot_T dt under the rate law; STICK pairs are not counted, since the
report treats them as not sliding (gdot_T = 0, 3.3.2): the regularized elastic part eps_T of
their motion is stored, not dissipated. That is the kernel's ``dissipation``, which dynamic
runs take (the mid-point rule's traction and rate). A quasi-static step prices only the slip
part of a SLIP pair's increment, (t^trial - t_T) / eps_T, on the cone mu t_N L_c averaged over
the step's ends (``engine.simulation._static_dissipation``): a pair that sticks at the step
start or reverses within it slips only once its traction has reached the cone.
"""

from __future__ import annotations

import numpy as np

__all__ = ["STICK", "SLIP"]

STICK = np.int8(0)
SLIP = np.int8(1)
