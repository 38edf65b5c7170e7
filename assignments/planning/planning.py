r"""Assignment 2: model probabilities, entropy, expected entropy and the next-best action.

The robot is shown one of ``L`` known objects (the identification paper's four boxes). Each model
``M_i`` has a pose EKF whose data likelihood (Eq. (9); ``data_log_likelihood`` of assignment 1) turns
into model probabilities by Bayes' rule (Eq. (7)). Their entropy (Eq. (5)) measures how unsure the
robot still is; the action that most reduces its *expected* entropy (Eqs. (4), (6), (10)) is the
next-best view. Expected measurements use the paper's cheap approximation, Eq. (15): ``W`` matched
features with a constant residual ``delta_o`` and covariance ``Sigma_o``.

Conventions used throughout:

* probabilities are NumPy vectors of shape (L,), entries in [0, 1], summing to 1;
* likelihoods are given and returned as natural logarithms: with dozens of features a likelihood is
  like ``exp(-2000)``, which is 0.0 in double precision. Work in log space (subtract the largest log
  before exponentiating: the log-sum-exp trick);
* entropies are in nats (natural log), with ``0 log 0 = 0``.

Write the functions below with NumPy (no ``lab`` imports). Run the public tests with
``python -m pytest test_planning.py``.
"""

import numpy as np


def model_probabilities(P_prior, log_likelihood, floor: float = 0.0) -> np.ndarray:
    r"""Bayes' rule for the model probabilities, Eq. (7), in log space, with a floor.

    .. math::

        P(M_i \mid \mathbf{D}_{1:k}) = \frac{p(\mathbf{D}_k \mid \cdot, M_i)\, P(M_i \mid \mathbf{D}_{1:k-1})}
        {\sum_j p(\mathbf{D}_k \mid \cdot, M_j)\, P(M_j \mid \mathbf{D}_{1:k-1})}

    then the floor, so that no model is ruled out for good by a few bad frames:

    .. math:: P_i \leftarrow \text{floor} + (1 - L\, \text{floor})\, P_i

    (every probability is at least ``floor`` and they still sum to 1).

    Parameters
    ----------
    P_prior : array_like, shape (L,)
        ``P(M_i | D_{1:k-1})``; entries may be 0 (``log 0 = -inf`` is fine: that model stays at 0
        before the floor). At least one entry is positive.
    log_likelihood : array_like, shape (L,)
        ``log p(D_k | D_{1:k-1}, M_i)``, natural log, finite, possibly very negative (e.g. -5000).
    floor : float, optional
        In ``[0, 1/L)``; 0 (the default) is plain Bayes.

    Returns
    -------
    P : ndarray, shape (L,)
        The posterior, summing to 1, every entry >= ``floor``.
    """
    ### BEGIN SOLUTION
    P_prior = np.asarray(P_prior, dtype=float)
    log_post = np.asarray(log_likelihood, dtype=float).copy()
    positive = P_prior > 0
    log_post[positive] += np.log(P_prior[positive])
    log_post[~positive] = -np.inf  # a model with prior 0 stays at 0
    log_post -= np.max(log_post)  # log-sum-exp: the largest term becomes exp(0) = 1
    post = np.exp(log_post)
    post /= post.sum()  # Eq. (7)'s denominator
    return floor + (1.0 - post.size * floor) * post
    ### END SOLUTION


def entropy(P) -> float:
    r"""The entropy of the model probabilities, Eq. (5), in nats.

    .. math:: H(M) = -\sum_i P_i \log P_i, \qquad 0 \log 0 = 0

    Parameters
    ----------
    P : array_like, shape (L,)
        Probabilities summing to 1 (some may be exactly 0).

    Returns
    -------
    float
        In ``[0, log L]``: 0 when one model is certain, ``log L`` for the uniform distribution.
    """
    ### BEGIN SOLUTION
    P = np.asarray(P, dtype=float)
    nz = P[P > 0]
    return float(-np.sum(nz * np.log(nz)))
    ### END SOLUTION


def feature_log_likelihood(W, delta_o, Sigma_o):
    r"""The log-likelihood of ``W`` expected feature matches, Eq. (15).

    With every matched feature's residual ``delta_o`` (3,) and covariance ``Sigma_o`` (3, 3) taken as
    constant (Eqs. (13)-(14)), the product of ``W`` Gaussians of Eq. (12) is

    .. math::

        \log p(\tilde{\mathbf{D}} \mid \theta, \mathbf{u}^+, M_j)
        = -\frac{W}{2} \left( 3 \log 2\pi + \log\lvert\Sigma_o\rvert
          + \delta_o^T \Sigma_o^{-1} \delta_o \right)

    (each feature is a 3-D Gaussian, hence ``3 log 2 pi``; the paper prints the normalisation as
    ``(2 pi)^(W/2)``, which drops that 3). With centimetre-sized ``Sigma_o`` the density per feature is
    above 1, so more matches mean a higher likelihood.

    Parameters
    ----------
    W : int or array_like of int, any shape
        Numbers of matched features (>= 0).
    delta_o : array_like, shape (3,) [m]
    Sigma_o : array_like, shape (3, 3) [m^2]
        Symmetric positive definite.

    Returns
    -------
    float or ndarray, the shape of ``W``
        Natural log.
    """
    ### BEGIN SOLUTION
    delta_o = np.asarray(delta_o, dtype=float)
    Sigma_o = np.asarray(Sigma_o, dtype=float)
    _, log_det = np.linalg.slogdet(Sigma_o)
    maha = float(delta_o @ np.linalg.solve(Sigma_o, delta_o))
    per_feature = -0.5 * (3.0 * np.log(2.0 * np.pi) + log_det + maha)
    return np.asarray(W, dtype=float) * per_feature
    ### END SOLUTION


def expected_entropy(P, W, delta_o, Sigma_o) -> float:
    r"""The expected model entropy after an action, Eq. (10) with the likelihood of Eq. (15).

    For each model ``M_i`` assumed to be the true one, the action's measurement would match ``W[i, j]``
    features of every model ``M_j`` (from the lookup tables). That gives the hypothetical posterior
    ``P^+(. | i)`` (Eq. (7), from ``P`` and the log-likelihoods ``feature_log_likelihood(W[i], ...)``,
    without a floor) and its entropy ``H^+_i``. The expectation weights them by the current ``P``:

    .. math:: E[H^+] = \sum_i P_i \, H\big(P^+(\cdot \mid i)\big)

    (one deterministic "sample" per model in Eq. (10)). Use your functions above.

    Parameters
    ----------
    P : array_like, shape (L,)
        Current model probabilities.
    W : array_like of int, shape (L, L)
        ``W[i, j]``: features of model ``M_j`` expected to match if ``M_i`` is the true model.
    delta_o : array_like, shape (3,) [m]
    Sigma_o : array_like, shape (3, 3) [m^2]

    Returns
    -------
    float
        In ``[0, log L]`` [nats]. Equal to ``entropy(P)`` when the action is uninformative (each row
        of ``W`` constant).
    """
    ### BEGIN SOLUTION
    P = np.asarray(P, dtype=float)
    log_lik = feature_log_likelihood(np.asarray(W), delta_o, Sigma_o)  # (L, L): row i = true model
    H = 0.0
    for i in range(P.size):
        if P[i] > 0:
            H += P[i] * entropy(model_probabilities(P, log_lik[i]))
    return float(H)
    ### END SOLUTION


def next_best_action(P, W_actions, delta_o, Sigma_o):
    r"""The next-best action, Eq. (6): the one with the largest information gain, Eq. (4).

    .. math:: I_{\mathbf{u}} = H(M) - E[H^+_{\mathbf{u}}], \qquad
        \mathbf{u}^* = \operatorname{argmax}_{\mathbf{u}} I_{\mathbf{u}}

    Parameters
    ----------
    P : array_like, shape (L,)
    W_actions : array_like of int, shape (A, L, L)
        The ``W`` matrix of each candidate action.
    delta_o : array_like, shape (3,) [m]
    Sigma_o : array_like, shape (3, 3) [m^2]

    Returns
    -------
    best : int
        Index of the best action; ties go to the smallest index.
    gains : ndarray, shape (A,)
        ``I_u`` of every action [nats].
    """
    ### BEGIN SOLUTION
    H_now = entropy(P)
    gains = np.array([H_now - expected_entropy(P, W, delta_o, Sigma_o) for W in np.asarray(W_actions)])
    return int(np.argmax(gains)), gains
    ### END SOLUTION
