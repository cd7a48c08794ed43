"""Where trial processes are started: a local pool of spawn-context worker processes
(:func:`run_local`) or Ray tasks (:func:`run_ray`). Either way one worker runs one trial
at a time as a ``mmexec run`` subprocess (:func:`~mmexec.executive.campaign.process.run_trial`)
and results are yielded as trials finish. A trial that exits 2 (bad input) stops the
campaign with an InputError naming the trial."""

from __future__ import annotations

import concurrent.futures
import logging
import multiprocessing
import os
import sys
from collections.abc import Iterable, Mapping, Sequence
from typing import Any

from mmexec.config.yamlload import InputError
from mmexec.executive.campaign.process import STOP_GRACE, run_trial
from mmexec.executive.campaign.trial import TrialResult, TrialSpec, parse_trial_log
from mmexec.executive.runner import ArgMark

__all__ = ["LOOPBACK", "RAY_SINGLE_MACHINE_ENV", "import_ray", "quiet_import_pybullet", "ray_init", "run_local",
           "run_ray"]

log = logging.getLogger(__name__)


def _input_error_from_trial(result: TrialResult) -> InputError:
    text = result.reason.removeprefix("bad input: ")
    return InputError.at(ArgMark(f"trial {result.index:04d}", 0, 0), f"{text} (command: {result.command})")


def silence_stderr() -> None:
    """Pool worker initializer: point file descriptor 2 at /dev/null, so C-level banners
    (pybullet's build line) printed while a worker imports do not reach the console.
    Trials write their own output to DIR/trials/NNNN.out; worker exceptions come back
    through the futures."""
    fd = os.open(os.devnull, os.O_WRONLY)
    os.dup2(fd, 2)
    os.close(fd)


def quiet_import_pybullet() -> None:
    """Import pybullet (if installed) with its build banner silenced, before the
    preflight loads skill modules that import it."""
    if "pybullet" in sys.modules:
        return
    sys.stderr.flush()
    saved = os.dup(2)
    try:
        silence_stderr()
        try:
            import pybullet  # noqa: F401
        except ImportError:
            log.debug("pybullet not installed; sim trials will report it")
    finally:
        os.dup2(saved, 2)
        os.close(saved)


def run_local(specs: Sequence[TrialSpec], workers: int, _address: str | None) -> Iterable[TrialResult]:
    """Trials on a spawn-context ProcessPoolExecutor, yielded as they finish."""
    ctx = multiprocessing.get_context("spawn")
    pool = concurrent.futures.ProcessPoolExecutor(max_workers=max(1, min(workers, len(specs))), mp_context=ctx,
                                               initializer=silence_stderr)
    futures = {pool.submit(run_trial, s): s for s in specs}
    try:
        for fut in concurrent.futures.as_completed(futures):
            spec = futures[fut]
            try:
                result = fut.result()
            except concurrent.futures.process.BrokenProcessPool as e:
                result = parse_trial_log(spec, exit_code=None, wall=float("nan"),
                                         note=f"worker process died: {e}")
            if result.exit_code == 2:
                raise _input_error_from_trial(result)
            yield result
    finally:
        pool.shutdown(wait=True, cancel_futures=True)


#: Ray reads this when it is imported: "0" selects its single-machine mode (its default on
#: macOS and Windows), where the node's address is 127.0.0.1 and every server of a local
#: instance (GCS, raylet, workers, agents) listens on loopback only. On Linux Ray
#: otherwise takes the machine's routable address and listens on all interfaces.
RAY_SINGLE_MACHINE_ENV = "RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER"
#: The only address a local Ray instance started for a campaign may listen on.
LOOPBACK = "127.0.0.1"


def import_ray(*, local: bool) -> Any:
    """Import Ray. ``local`` (``--ray`` without an address): select Ray's single-machine
    mode first (:data:`RAY_SINGLE_MACHINE_ENV`), so the instance started for the campaign
    listens on 127.0.0.1 only; a cluster address is left to Ray."""
    if local:
        os.environ[RAY_SINGLE_MACHINE_ENV] = "0"
    try:
        import ray
    except ImportError:
        raise InputError.at(ArgMark("--ray", 0, 0), "Ray is not installed in this environment "
                            "(pip install 'ray>=2.9'); run without --ray for local processes") from None
    return ray


def ray_init(ray: Any, workers: int, address: str | None) -> bool:
    """Connect to the cluster at ``address`` or, for ``""``, start a local instance with
    ``workers`` CPUs that listens on 127.0.0.1 only, unless Ray is initialised already
    (then the caller's instance is used). Returns True when this call initialised Ray
    (the caller shuts it down). A local instance on another address (Ray imported in this
    process before :func:`import_ray` could select loopback) is shut down again and is
    an InputError naming ``--ray``."""
    if ray.is_initialized():
        return False
    env = {k: os.environ[k] for k in ("PYTHONPATH", "MMEXEC_DEBUG") if k in os.environ}
    kwargs: dict[str, Any] = {"include_dashboard": False, "log_to_driver": False, "configure_logging": False}
    if env:
        kwargs["runtime_env"] = {"env_vars": env}
    if address:
        ray.init(address=address, **kwargs)
        return True
    ray.init(num_cpus=max(1, workers), **kwargs)
    node = ray.util.get_node_ip_address()
    if node != LOOPBACK:
        ray.shutdown()
        raise InputError.at(ArgMark("--ray", 0, 0), f"a local Ray instance would listen on {node}, not {LOOPBACK} "
                            f"(Ray was imported before {RAY_SINGLE_MACHINE_ENV}=0 could be set); set it in the "
                            "environment, or start a cluster yourself and pass its address")
    return True


def run_ray(specs: Sequence[TrialSpec], workers: int, address: str | None) -> Iterable[TrialResult]:
    """Trials as Ray tasks (one CPU each) on the cluster at ``address`` or, for ``""``,
    on a local Ray instance started for this campaign (``workers`` CPUs, listening on
    127.0.0.1 only: :func:`ray_init`)."""
    ray = import_ray(local=not address)
    started = ray_init(ray, workers, address)
    try:
        task = ray.remote(num_cpus=1, max_retries=0)(run_trial)
        refs = {task.remote(s): s for s in specs}
        waiting = list(refs)
        try:
            yield from _ray_results(ray, refs, waiting)
        except KeyboardInterrupt:
            # cancel raises KeyboardInterrupt inside running tasks: they pass it to their trial
            for ref in waiting:
                ray.cancel(ref)
            ray.wait(waiting, num_returns=len(waiting), timeout=STOP_GRACE + 5.0)
            raise
    finally:
        if started:
            ray.shutdown()


def _ray_results(ray: Any, refs: Mapping[Any, TrialSpec], waiting: list[Any]) -> Iterable[TrialResult]:
    """Yield results as Ray tasks finish; ``waiting`` (the refs not finished) is updated
    in place so the caller can cancel what is left."""
    while waiting:
        ready, rest = ray.wait(waiting, num_returns=1)
        waiting[:] = rest
        for ref in ready:
            spec = refs[ref]
            try:
                result = ray.get(ref)
            except ray.exceptions.RayError as e:
                msg = str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
                result = parse_trial_log(spec, exit_code=None, wall=float("nan"),
                                         note=f"Ray task failed: {type(e).__name__}: {msg}")
            if result.exit_code == 2:
                for r in waiting:
                    ray.cancel(r, force=True)
                raise _input_error_from_trial(result)
            yield result
