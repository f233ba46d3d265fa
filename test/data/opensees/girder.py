"""A three-span girder in OpenSeesPy, the same structure as the built-in girder kind of
test/test_opensees_import.py: spans 16, 24, 16 m, 8 Euler-Bernoulli elements per span with consistent
mass, vertical bearing springs at the four supports, plane bending only (axial DOFs fixed).

Parameters for ``shm-ros import opensees``: 1 = E of every beam element, 2 = every bearing's spring.
Written for this project's tests (licence of the project)."""

import numpy as np
import openseespy.opensees as ops

SPANS = [16.0, 24.0, 16.0]
N_PER_SPAN = 8
E, INERTIA, A, RHO = 3.4e10, 2.1, 5.2, 2500.0
K_BEARING = 4.0e8

ops.wipe()
ops.model("basic", "-ndm", 2, "-ndf", 3)
ends = np.concatenate([[0.0], np.cumsum(SPANS)])
xs = np.unique(np.round(np.concatenate([np.linspace(a, b, N_PER_SPAN + 1)
                                        for a, b in zip(ends[:-1], ends[1:], strict=True)]), 9))
for i, x in enumerate(xs, start=1):
    ops.node(i, float(x), 0.0)
    ops.fix(i, 1, 0, 0)  # plane bending: no axial motion
ops.geomTransf("Linear", 1)
for e in range(1, len(xs)):
    ops.element("elasticBeamColumn", e, e, e + 1, A, E, INERTIA, 1, "-mass", RHO * A, "-cMass")
ops.uniaxialMaterial("Elastic", 1, K_BEARING)
for j, x in enumerate(ends):
    deck = int(np.argmin(np.abs(xs - x))) + 1
    ground = 1000 + j
    ops.node(ground, float(x), 0.0)
    ops.fix(ground, 1, 1, 1)
    ops.element("zeroLength", 100 + j, ground, deck, "-mat", 1, "-dir", 2)

ops.parameter(1, "element", 1, "E")
for e in range(2, len(xs)):
    ops.addToParameter(1, "element", e, "E")
ops.parameter(2, "element", 100, "material", 1, "E")
for j in range(1, len(ends)):
    ops.addToParameter(2, "element", 100 + j, "material", 1, "E")
