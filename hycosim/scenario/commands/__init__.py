"""The grasp demo's commands (``scene``, ``camera``, ``train``, ``evaluate``, ``trials``, ``krl``)."""
