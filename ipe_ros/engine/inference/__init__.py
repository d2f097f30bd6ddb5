"""Inference room: an object's unknown properties (mass, friction, restitution) from observed motion.

observation.py (the ``ipe_ros.observation/1``
input, checked once; its priors are the scene's, ``scene/properties.py``), likelihood.py (how far a rollout stays from the
frames, with the physics' own error), particle.py (one candidate's rollout, run by the workers),
amis.py (the sampler: adaptive importance sampling as a plan of the one Monte Carlo loop),
infer.py (the answer), known.py (observations made at known properties: the tests' analytic cases, the worked example).
Sits beside ``sampling/``: it uses the rollout, and nothing below imports it.
"""
