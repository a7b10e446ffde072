"""The seed's perturbation study, rebuilt: energy (chapter 2) and bounce (chapter 3) analyses.

- :mod:`.trajectory`: the trajectories the analyses evaluate (any ``t, theta, phi,
  theta_dot, phi_dot, u``; closed-loop runs with the rigid or the contact plant).
- :mod:`.energy`: energy and energy fluctuation of the ideal system and of each
  perturbation (seed eqs. 2.1-2.15), rankings, the bump estimate, plots.
- :mod:`.bounce`: the discrete impact model (seed eqs. 3.1-3.16), paths A/B/C, threshold
  bump height, slip; the contact model over a row of bumps in closed loop; the seed's
  Taylor closest point against the exact one.
- :mod:`.recorded`: the seed's recommendation 2 on real recordings: motor work against the
  ideal energy input, their discrepancy per turn and over the run beside the chapter-2
  energies, before and after ``bfr diagnose``'s correction.
- :mod:`.edges`: the seed's recommendation 3 with the two-edge contact model: bumps on both
  plate edges, when they cancel and when they add.
- :mod:`.cli`: ``bfr analyze energy|bounce|edges|rough``.
"""
