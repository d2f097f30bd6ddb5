"""The checking room: answers that check their fast physics against converged physics.

``fidelity`` (the rules: unhealthy rollouts, differences, escalation, the verdicts, the reference
settings), ``bias`` (each outcome's bias by stratum, the confirmation and coverage picks), ``self_check`` (the check of one answer's samples
as a plan of reruns, driven by the Monte Carlo loop beside or after the fast samples).
"""
