"""The sampling room: the Monte Carlo IPE (paper Eq. S5).

``montecarlo`` (the one loop: plans of tasks, seeds, the injected map, the budget's deadline),
``perturb`` (each sample's noise, masses and push), ``rollout`` (one sample end to end, in a
worker), ``estimate`` (the answer: Prediction), ``decide`` (when a decision question may stop
sampling). A prediction as a plan (predict, predict_many) is the room above the self-check
(``engine/predict.py``); what a sample leaves and the statistics are the room below the queries
(``engine/results``).
"""
