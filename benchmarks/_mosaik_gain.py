"""One mosaik 3 simulator (a `cmd` process) of the barrier benchmark's ring: y = 0.5·u + 1."""

import mosaik_api_v3

META = {"api_version": "3.0", "type": "time-based",
        "models": {"Gain": {"public": True, "params": [], "attrs": ["u", "y"]}}}


class GainSim(mosaik_api_v3.Simulator):
    """The ring's gain as a mosaik simulator: one entity, y = 0.5·u + 1."""

    def __init__(self):
        super().__init__(META)
        self.y = 1.0

    def init(self, sid, time_resolution=1.0, **kwargs):
        """mosaik's handshake: the simulator's meta data."""
        return self.meta

    def create(self, num, model, **kwargs):
        """The one gain entity."""
        return [{"eid": "g", "type": model}]

    def step(self, time, inputs, max_advance):
        """y from the inputs' sum; the next step is one time unit on."""
        u = sum(inputs["g"]["u"].values()) if inputs.get("g") else 0.0
        self.y = 0.5 * u + 1.0
        return time + 1

    def get_data(self, outputs):
        """The entity's y."""
        return {"g": {"y": self.y}}


if __name__ == "__main__":
    mosaik_api_v3.start_simulation(GainSim())
