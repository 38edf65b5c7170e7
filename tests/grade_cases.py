"""Realistic wrong submissions, kept as one-line edits of the reference solutions.

Each case names the graded tests it must fail (all others must pass) and, for some of them, words the
failure message must contain so that it points at the mistake. A case whose edit no longer applies
(the reference changed) fails loudly instead of silently testing the reference.
"""

from __future__ import annotations

from dataclasses import dataclass, field


@dataclass(frozen=True)
class WrongSubmission:
    name: str
    assignment: str
    old: str  # text of the reference solution to replace (must occur exactly once)
    new: str
    fails: frozenset[str]  # graded test ids that must fail; every other test must pass
    says: dict[str, str] = field(default_factory=dict)  # test id -> words its message must contain
    more: tuple[tuple[str, str], ...] = ()  # further (old, new) edits, for mistakes made together

    def source(self, reference: str) -> str:
        for old, new in ((self.old, self.new), *self.more):
            n = reference.count(old)
            if n != 1:
                raise AssertionError(
                    f"case {self.name}: an edit matches {n} times in the reference, not once"
                )
            reference = reference.replace(old, new)
        return reference


ALL = "*"  # every test of the assignment

CASES = [
    WrongSubmission(
        "jacobian_sign_error",
        "ekf",
        "dRy = np.array([[-sb, 0.0, cb], [0.0, 0.0, 0.0], [-cb, 0.0, -sb]])",
        "dRy = np.array([[-sb, 0.0, -cb], [0.0, 0.0, 0.0], [cb, 0.0, -sb]])",  # d/db of Ry with a sign slip
        frozenset({"jacobian_finite_differences", "ekf_update_one_step", "ekf_consistency"}),
        {
            "jacobian_finite_differences": "column(s) 4 (d/d beta)",
            "ekf_consistency": "measurement_jacobian, which fails its own tests",
        },
    ),
    WrongSubmission(
        "jacobian_wrong_shape",
        "ekf",
        "    return C.reshape(3 * n, 6)\n",
        "    return C\n",  # (n, 3, 6): forgot to stack
        frozenset(
            {
                "jacobian_shape_and_translation",
                "jacobian_finite_differences",
                "ekf_update_one_step",
                "ekf_consistency",
            }
        ),
        {"jacobian_shape_and_translation": "returned shape (1, 3, 6); expected shape (3, 6)"},
    ),
    WrongSubmission(
        "kalman_returns_the_prior_covariance",
        "ekf",
        "    return mu, 0.5 * (Sigma + Sigma.T)\n",
        "    return mu, Sigma_bar  # the covariance update: later\n",
        frozenset(
            {
                "kalman_update_matches_equations",
                "kalman_update_covariance",
                "ekf_update_one_step",
                "ekf_consistency",
            }
        ),
        {"kalman_update_covariance": "equals Sigma_bar"},
    ),
    WrongSubmission(
        "jacobian_rotation_columns_left_zero",
        "ekf",
        "        C[:, :, 3 + k] = b @ dR[k].T  # d d_j / d theta_k = (dR/dtheta_k) b_j\n",
        "        pass  # the rotation columns: later\n",
        frozenset(
            {
                "jacobian_shape_and_translation",
                "jacobian_finite_differences",
                "ekf_update_one_step",
                "ekf_consistency",
            }
        ),
        {"jacobian_shape_and_translation": "rotation columns"},
    ),
    WrongSubmission(
        # both wrong at once: each hides the other in a round trip
        "triangulate_homogeneous_and_project_drops_depth",
        "stereo",
        "    out[ok, 0] = (uv[ok, 0] - cx) * Z / f\n"
        "    out[ok, 1] = (uv[ok, 1] - cy) * Z / f\n"
        "    out[ok, 2] = Z\n",
        "    out[ok, 0] = uv[ok, 0]\n    out[ok, 1] = uv[ok, 1]\n    out[ok, 2] = 1.0\n",
        frozenset(
            {
                "triangulate_matches_opencv",
                "triangulate_invalid_disparity",
                "project_matches_opencv",
                "round_trip",
            }
        ),
        {"triangulate_invalid_disparity": "disparities 8 and 25", "round_trip": "triangulate(project("},
        more=(
            (
                "    out[ok, 0] = f * p[ok, 0] / p[ok, 2] + cx\n"
                "    out[ok, 1] = f * p[ok, 1] / p[ok, 2] + cy\n",
                "    out[ok, 0] = p[ok, 0]\n    out[ok, 1] = p[ok, 1]\n",
            ),
        ),
    ),
    WrongSubmission(
        "depth_std_linear_in_depth",
        "stereo",
        "    return Z**2 * sigma_disparity / (f * baseline)\n",
        "    return Z * sigma_disparity / (f * baseline)\n",
        frozenset({"depth_std_monte_carlo"}),
    ),
    WrongSubmission(
        "unnormalised_posterior",
        "planning",
        "    post /= post.sum()  # Eq. (7)'s denominator\n",
        "",
        frozenset(
            {
                "posterior_bayes",
                "posterior_log_space",
                "posterior_floor",
                "posterior_recursive",
                "expected_entropy_value",
                "expected_entropy_properties",
                "next_best_action_choice",
            }
        ),
        {
            "posterior_bayes": "not 1: normalise by Eq. (7)'s denominator",
            "expected_entropy_value": "model_probabilities, which fails its own tests",
        },
    ),
    WrongSubmission(
        "entropy_of_zero_is_nan",
        "planning",
        "    nz = P[P > 0]\n    return float(-np.sum(nz * np.log(nz)))",
        "    return float(-np.sum(P * np.log(P)))",
        # expected_entropy meets exact zeros only with hundreds of features (its posteriors underflow)
        frozenset({"entropy_zero_probabilities", "expected_entropy_properties"}),
        {"entropy_zero_probabilities": "0 * log 0 gives NaN"},
    ),
    WrongSubmission(
        "alpha_beta_swapped",
        "search",
        "        lik = np.full(shape, alpha, dtype=float)  # a false alarm: the object is elsewhere\n"
        "        lik[u, v] = 1.0 - beta  # a true detection\n"
        "    else:\n"
        "        lik = np.full(shape, 1.0 - alpha, dtype=float)  # correctly nothing\n"
        "        lik[u, v] = beta  # a missed detection",
        "        lik = np.full(shape, beta, dtype=float)\n"
        "        lik[u, v] = 1.0 - alpha\n"
        "    else:\n"
        "        lik = np.full(shape, 1.0 - beta, dtype=float)\n"
        "        lik[u, v] = alpha",
        frozenset(
            {
                "detection_likelihood_eq2",
                "map_update_normalised",
                "map_update_miss",
                "map_update_hit",
                "map_update_other_cells",
                "map_update_sequence",
            }
        ),
        {
            "detection_likelihood_eq2": "alpha and beta swapped",
            "map_update_normalised": "alpha and beta swapped",
            "map_update_miss": "alpha and beta swapped",
            "map_update_sequence": "alpha and beta swapped",
        },
    ),
    WrongSubmission(
        "manhattan_heuristic",
        "search",
        "    return min_cost * (max(di, dj) + (math.sqrt(2.0) - 1.0) * min(di, dj))",
        "    return min_cost * (di + dj)",  # not admissible with diagonal steps
        frozenset({"heuristic_octile", "heuristic_admissible", "astar_optimal", "astar_large_map"}),
        {
            "heuristic_octile": "Manhattan distance, which overestimates",
            "heuristic_admissible": "overestimates",
            "astar_optimal": "heuristic never overestimates",
        },
    ),
    WrongSubmission(
        "astar_infinite_loop",
        "search",
        "        _, g_u, u = heapq.heappop(open_list)",
        "        _, g_u, u = open_list[0]",  # peeked instead of popped: the loop never ends
        frozenset({"astar_valid_path", "astar_optimal", "astar_no_path", "astar_large_map"}),
        {"astar_valid_path": "astar did not return within this test's limit of 5 s"},
    ),
    WrongSubmission(
        "crash_on_import",
        "search",
        "\n\ndef detection_likelihood(",
        "\n\nprint(astar(np.ones((5, 5)), (0, 0), (4, 4)))  # a quick check, left behind\n"
        "\n\ndef detection_likelihood(",
        frozenset({ALL}),
        {ALL: "importing search.py failed: NameError: name 'astar' is not defined"},
    ),
]


def make_class(folder, names: tuple[str, ...] | None = None) -> list[str]:
    """A generated class in ``folder``: for each assignment in ``names`` (default all) a student with
    the reference solution, one with the untouched student template, and one per wrong submission
    above; each student folder holds that one module. Returns the student names."""
    from pathlib import Path

    from lab.grading import list_assignments
    from lab.grading.release import release

    folder = Path(folder)
    chosen = [a for a in list_assignments() if names is None or a.name in names]
    templates = folder.parent / f".{folder.name}-release"
    release(chosen, templates, force=True)
    students = []
    for a in chosen:
        ref = a.module_path.read_text()
        subs = {f"{a.name}_reference": ref, f"{a.name}_template": (templates / a.name / a.module).read_text()}
        subs.update({f"{a.name}_{c.name}": c.source(ref) for c in CASES if c.assignment == a.name})
        for student, text in subs.items():
            (folder / student).mkdir(parents=True)
            (folder / student / a.module).write_text(text)
            students.append(student)
    return students
