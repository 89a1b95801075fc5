"""A batch's pairs run on a Dask cluster: the scheduler's address checked from its form
(``check_scheduler_address``) before ``connect``, and ``run_dask``, whose tasks
(``match_pair_on_worker``) the cluster's worker threads run, a few a thread in flight.
"""

from __future__ import annotations

import re
import time
from typing import Any, Callable, Dict, Iterable, Iterator, List

from .batch import INTERNAL, BatchError, Pair, bounded, error_line, match_pair
from .config import Config
from .errors import internal_error

#: Pairs submitted per worker and not yet finished: 2 keeps a worker busy while the main process
#: writes the line of the pair it just finished, and bounds the main process's memory.
IN_FLIGHT_PER_WORKER = 2
#: How long to try to reach a Dask scheduler before giving up, s.
DASK_CONNECT_TIMEOUT_S = 10.0
#: How often the number of Dask worker threads (hence the in-flight bound) is asked again, s.
DASK_RECHECK_S = 5.0
#: Schemes of a Dask scheduler address (distributed's comm backends; ``inproc`` for a cluster
#: in this process) and the form of an address: scheme://host:port, or host:port (tcp).
DASK_SCHEMES = ("tcp", "tls", "ws", "wss", "ucx")
DASK_ADDRESS = re.compile(r"^(?:(?P<scheme>[a-z]+)://)?(?P<host>\[[0-9a-fA-F:.]+\]|[^\s:/\[\]]+)"
                          r":(?P<port>[0-9]{1,5})/?$")


def check_scheduler_address(address: str) -> str:
    """``address`` when it has the form of a Dask scheduler address, else ``BatchError`` saying
    the form: scheme://host:port with a scheme of ``DASK_SCHEMES``, host:port (tcp), or an
    ``inproc://`` address (a cluster in this process). Checked before connecting, so a malformed
    address fails at once rather than after the connection's time-out.

    >>> check_scheduler_address("tcp://127.0.0.1:8786")
    'tcp://127.0.0.1:8786'
    >>> check_scheduler_address("127.0.0.1")
    Traceback (most recent call last):
    ...
    scalematch.batch.BatchError: --scheduler 127.0.0.1: no port; a Dask scheduler address is scheme://host:port, e.g. tcp://127.0.0.1:8786 (schemes: tcp, tls, ws, wss, ucx)
    """
    form = ("a Dask scheduler address is scheme://host:port, e.g. tcp://127.0.0.1:8786 "
            f"(schemes: {', '.join(DASK_SCHEMES)})")
    if address.startswith("inproc://") and len(address) > len("inproc://"):
        return address
    found = DASK_ADDRESS.match(address.strip())
    scheme = found.group("scheme") if found else address.partition("://")[0].lower() \
        if "://" in address else None
    if scheme in ("http", "https"):
        raise BatchError(f"--scheduler {address}: http is the dashboard's address, not the "
                         f"scheduler's; {form}")
    if found is None:
        what = "no port" if ":" not in (address.partition("://")[2] or address) else \
            "not an address"
        raise BatchError(f"--scheduler {address}: {what}; {form}")
    if scheme is not None and scheme not in DASK_SCHEMES:
        raise BatchError(f"--scheduler {address}: unknown scheme {scheme!r}; {form}")
    if not 1 <= int(found.group("port")) <= 65535:
        raise BatchError(f"--scheduler {address}: port {found.group('port')} is not 1-65535; "
                         f"{form}")
    return address


def connect(address: str, timeout: float = DASK_CONNECT_TIMEOUT_S) -> Any:
    """A ``distributed.Client`` of the Dask scheduler at ``address`` (e.g. tcp://host:8786),
    whose form is checked first (:func:`check_scheduler_address`)."""
    check_scheduler_address(address)
    try:
        from distributed import Client
    except ImportError:
        raise BatchError("a Dask scheduler needs dask.distributed, which is not installed; "
                         "install it with: pip install 'scalematch[dask]'") from None
    try:
        return Client(address, timeout=timeout, set_as_default=False)
    except (OSError, TimeoutError, ValueError, TypeError) as exc:
        raise BatchError(f"cannot reach the Dask scheduler at {address}: {exc}") from None


def match_pair_on_worker(pair: Pair, config: Config, max_pixels: int) -> Dict[str, Any]:
    """``match_pair`` as a Dask task: one OpenCV thread per task (the worker threads are the
    parallelism, as the processes of the local pool)."""
    import cv2

    cv2.setNumThreads(1)
    return match_pair(pair, config, max_pixels)


def _dask_threads(client: Any) -> Callable[[], int]:
    """Worker threads of the cluster (at least 1), asked again every DASK_RECHECK_S seconds."""
    state = {"at": -float("inf"), "n": 1}

    def threads() -> int:
        if time.monotonic() - state["at"] > DASK_RECHECK_S:
            state["n"] = max(1, sum(client.nthreads().values()))
            state["at"] = time.monotonic()
        return state["n"]
    return threads


def _dask_wait_first(client: Any, futures: List[Any]) -> Iterable[Any]:
    """The done ones of ``futures`` once at least one is (``distributed.wait`` uses the current
    client: this one, not a default the caller may not have set)."""
    from distributed import wait

    with client.as_current():
        return wait(futures, return_when="FIRST_COMPLETED").done


def run_dask(pairs: Iterable[Pair], config: Config, max_pixels: int,
             client: Any) -> Iterator[Dict[str, Any]]:
    """The lines of ``pairs``, matched on the Dask cluster of ``client``, in the order they finish.

    The workers must have scalematch installed (the same version) and see the image files under
    the paths given (relative paths are resolved on this machine). When the iteration stops early
    the unfinished tasks are cancelled; their pairs get no line, so a resumed batch redoes them.
    """
    threads = _dask_threads(client)
    yield from bounded(
        pairs,
        submit=lambda pair: client.submit(match_pair_on_worker, pair, config, max_pixels,
                                          pure=False),
        wait_first=lambda fs: _dask_wait_first(client, fs),
        outcome=lambda fut, pair: _outcome(fut, pair, config),
        limit=lambda: IN_FLIGHT_PER_WORKER * threads(), stop=client.cancel)


def _outcome(future: Any, pair: Pair, config: Config) -> Dict[str, Any]:
    """The line of a finished future; an error line when its worker failed (died, cancelled)."""
    try:
        return future.result()
    except Exception as exc:  # noqa: BLE001 (its worker failed, not its pair's files)
        return error_line(pair, f"{internal_error(exc)} (its worker failed)", config,
                          kind=INTERNAL)
