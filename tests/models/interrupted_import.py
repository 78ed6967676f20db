"""A model module whose import is cut short by Ctrl-C the way a C extension's is: the
KeyboardInterrupt raised while it initialises comes out as ImportError("initialization failed")."""

import os
import signal

try:
    os.kill(os.getpid(), signal.SIGINT)
    signal.sigwait  # noqa: B018 - any bytecode gives the interpreter the chance to run the handler
except KeyboardInterrupt:
    raise ImportError("initialization failed") from None


class Never:  # pragma: no cover - the import never completes
    pass
