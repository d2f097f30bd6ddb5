"""The sampling room: the Monte Carlo IPE (paper Eq. S5).

``montecarlo`` (the one loop: plans of tasks, seeds, the injected map, the budget's deadline),
``sampler`` (a prediction as a plan; predict, predict_many), ``perturb`` (each sample's noise,
masses and push), ``rollout`` (one sample end to end, in a worker), ``outcome`` (what a sample leaves:
common fields and its query values), ``estimate`` (the answer: Prediction), ``stats`` (intervals,
circular statistics), ``decide`` (when a decision question may stop sampling).
"""
