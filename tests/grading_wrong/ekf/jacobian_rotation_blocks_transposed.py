"""measurement_jacobian multiplies by dR^T instead of dR: the rotation columns hold (dR/dtheta)^T b_j.

Base: reference
Fails: jacobian_shape_and_translation, jacobian_finite_differences, ekf_update_one_step, ekf_consistency
"""

import numpy as np


def measurement_jacobian(X, b_O):
    X = np.asarray(X, dtype=float)
    b = np.asarray(b_O, dtype=float).reshape(-1, 3)
    ca, sa = np.cos(X[3]), np.sin(X[3])
    cb, sb = np.cos(X[4]), np.sin(X[4])
    cg, sg = np.cos(X[5]), np.sin(X[5])
    Rz = np.array([[ca, -sa, 0.0], [sa, ca, 0.0], [0.0, 0.0, 1.0]])
    Ry = np.array([[cb, 0.0, sb], [0.0, 1.0, 0.0], [-sb, 0.0, cb]])
    Rx = np.array([[1.0, 0.0, 0.0], [0.0, cg, -sg], [0.0, sg, cg]])
    dRz = np.array([[-sa, -ca, 0.0], [ca, -sa, 0.0], [0.0, 0.0, 0.0]])
    dRy = np.array([[-sb, 0.0, cb], [0.0, 0.0, 0.0], [-cb, 0.0, -sb]])
    dRx = np.array([[0.0, 0.0, 0.0], [0.0, -sg, -cg], [0.0, cg, -sg]])
    dR = (dRz @ Ry @ Rx, Rz @ dRy @ Rx, Rz @ Ry @ dRx)
    n = b.shape[0]
    C = np.zeros((n, 3, 6))
    C[:, :, :3] = np.eye(3)
    for k in range(3):
        C[:, :, 3 + k] = b @ dR[k]  # should be b @ dR[k].T
    return C.reshape(3 * n, 6)
