"""The thesis's chapter-5 experiments as runnable definitions (``swingrt experiment``).

Each ``*.toml`` here defines: the controlled ``axes``; the ``controllers`` compared
(``pid``, ``lqr``, ``mpc``); the velocity ``step``; the run ``duration``; scenario overrides
``[common]`` (training and evaluation), ``[training]`` and ``[evaluation]``; and an optional
``[grid]`` of dotted scenario keys whose product makes the cases. For every case the runner
flies the training flight under PX4 PID, identifies the DMDc model (search) for the MPC and
the white-box parameters for the LQR, then flies the step with every controller.
"""
