"""One HELICS federate (or the broker) of the barrier benchmark's ring: y = 0.5·u + 1."""

import sys
import time

import helics as h


def broker(core: str, n: int, port: int) -> None:
    """Run HELICS's broker for ``n`` federates on ``port`` until they have all left."""
    b = h.helicsCreateBroker(core, "", f"-f {n} --name=bench --local_interface=127.0.0.1 --port={port}")
    while h.helicsBrokerIsConnected(b):
        time.sleep(0.05)
    h.helicsCloseLibrary()


def federate(core: str, n: int, i: int, steps: int, port: int) -> None:
    """Run federate ``i`` of the ring for ``steps`` time steps (y = 0.5·u + 1 on its predecessor's y);
    the first prints the ring's steps/s."""
    fi = h.helicsCreateFederateInfo()
    h.helicsFederateInfoSetCoreTypeFromString(fi, core)
    h.helicsFederateInfoSetCoreInitString(fi, f"--federates=1 --broker_address=127.0.0.1 --brokerport={port}")
    h.helicsFederateInfoSetTimeProperty(fi, h.HELICS_PROPERTY_TIME_PERIOD, 1.0)
    fed = h.helicsCreateValueFederate(f"n{i}", fi)
    pub = h.helicsFederateRegisterGlobalPublication(fed, f"y{i}", h.HELICS_DATA_TYPE_DOUBLE, "")
    sub = h.helicsFederateRegisterSubscription(fed, f"y{(i - 1) % n}", "")
    h.helicsInputSetDefaultDouble(sub, 0.0)
    h.helicsFederateEnterExecutingMode(fed)
    h.helicsPublicationPublishDouble(pub, 1.0)
    t0 = time.perf_counter()
    for k in range(1, steps + 1):
        h.helicsFederateRequestTime(fed, float(k))
        u = h.helicsInputGetDouble(sub)
        h.helicsPublicationPublishDouble(pub, 0.5 * u + 1.0)
    elapsed = time.perf_counter() - t0
    if i == 0:
        print(f"{steps / elapsed} {u}", flush=True)
    h.helicsFederateDisconnect(fed)
    h.helicsFederateFree(fed)
    h.helicsCloseLibrary()


if __name__ == "__main__":
    role, core, n = sys.argv[1], sys.argv[2], int(sys.argv[3])
    if role == "broker":
        broker(core, n, int(sys.argv[4]))
    else:
        federate(core, n, int(sys.argv[4]), int(sys.argv[5]), int(sys.argv[6]))
