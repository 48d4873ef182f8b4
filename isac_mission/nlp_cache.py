"""Compiled IPOPT problems, cached on disk: an IpoptFactory (planning/nlp_model.py) for the CLI.

CasADi evaluates an NLP's functions (objective, constraints, their Jacobian and the Lagrangian's
Hessian) in its interpreter; compiled to C they run the same operations in the same order (the
horizon's evaluations at M = 3 about twelve times faster, its plans 1.7 times: docs/performance.md,
"Compiled problems"), and give the same numbers
(tests/integration/test_nlp_cache.py). A compile takes a C compiler and long (about 20 s for the
horizon at M = 3, minutes at M = 12), so it never runs inside a plan:

- `CompiledNlpCache(directory, compile=...)` loads a problem's compiled solver from the cache when
  it is there (a file per problem: its key hashes the NLP's expressions, options, CasADi's version
  and the compiler flags, so any change of scenario or code is a new file; a derivative given as
  an option, the horizon's Hessian, is compiled too and enters the key by what it computes);
- a second solver of the same NLP with other options (`like`: the horizon's warm-start instance)
  takes the first one's compiled derivatives: one compile serves both;
- otherwise it returns the interpreted solver at once and, with `compile="background"`, compiles
  in a child process (niced, one at a time) and switches to the compiled solver at its first solve
  after the file is written; with `compile="now"` it compiles before returning
  (`isac-mission compile`);
- with no C compiler (the project's Docker image has none), `ISAC_MISSION_COMPILE=off`, or a
  cache file that does not load, the interpreted solver plans as before.

I/O (files, a compiler, a child process) lives here, not in planning/.
"""

from __future__ import annotations

import atexit
import hashlib
import json
import logging
import os
import queue
import shutil
import subprocess
import sys
import tempfile
import threading
import time
import weakref
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import casadi as ca

from isac_mission.planning.nlp_model import NlpSolver, plain_ipopt

LOG = logging.getLogger(__name__)

CACHE_ENV = "ISAC_MISSION_NLP_CACHE"
"""Environment variable: the cache directory (default: $XDG_CACHE_HOME/isac-mission/nlp, or
~/.cache/isac-mission/nlp)."""

COMPILE_ENV = "ISAC_MISSION_COMPILE"
"""Environment variable: `off` turns compiling off (cached problems still load)."""

COMPILER_ENV = "ISAC_MISSION_CC"
"""Environment variable: the C compiler (default: gcc, else cc, on PATH)."""

JIT_FLAGS = ("-O1",)
"""-O1: at M = 3 the horizon's evaluations as fast as with -O2 (3.7 against 4.0 ms a solve)
at a fifth of the compile time (21 against 110 s); -O0 compiles in half the time of -O1 but at
M = 12 evaluated slower than the interpreter."""

FORMAT = 2
"""Bumped when what a cache file holds changes (2: Function-valued options compiled too)."""

_EVENT_KINDS = (
    (": compiled, loaded from the cache", "loaded compiled from the cache"),
    (": shares the compiled derivatives of ", "sharing another's compiled derivatives"),
    ("is compiled (shares it)", "sharing a compile under way"),
    ("is compiled (in the background)", "interpreted while they compile in the background"),
    (": compiled in ", "compiled while the mission flew"),
    ("not in the cache)", "interpreted (nothing to compile them with)"),
)
"""How `CompiledNlpCache.events` read, by the words that mark each kind, for `events_summary`."""


def events_summary(events: Sequence[str]) -> list[str]:
    """The cache's events in one line of counts by kind ("6 loaded compiled from the cache,
    3 sharing another's compiled derivatives"), then every event of no usual kind (a file that
    did not load, a compile that failed) as it was said."""
    counts: dict[str, int] = {}
    unusual: list[str] = []
    for event in events:
        kind = next((k for marker, k in _EVENT_KINDS if marker in event), None)
        if kind is None:
            unusual.append(event)
        else:
            counts[kind] = counts.get(kind, 0) + 1
    line = ", ".join(f"{n} {kind}" for kind, n in counts.items())
    return [line, *unusual] if line else unusual


CompileMode = Literal["never", "background", "now"]


def default_cache_dir() -> Path:
    """$ISAC_MISSION_NLP_CACHE, else $XDG_CACHE_HOME/isac-mission/nlp, else
    ~/.cache/isac-mission/nlp."""
    if os.environ.get(CACHE_ENV):
        return Path(os.environ[CACHE_ENV])
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "isac-mission" / "nlp"


def find_compiler() -> str | None:
    """The C compiler to use: $ISAC_MISSION_CC (if it runs), else gcc or cc on PATH; None if
    there is none or ISAC_MISSION_COMPILE=off."""
    if os.environ.get(COMPILE_ENV, "").strip().lower() == "off":
        return None
    named = os.environ.get(COMPILER_ENV)
    for candidate in [named] if named else ["gcc", "cc"]:
        path = shutil.which(candidate)
        if path:
            return path
    return None


def jit_options(compiler: str, directory: Path, jit_name: str = "nlp") -> dict[str, Any]:
    """A Function's (or nlpsol's) options that compile it (its functions) with `compiler` into
    `directory`/jit_name and keep the shared object there (the saved solver links to it: loading
    needs no compiler)."""
    return {
        "jit": True,
        "compiler": "shell",
        "jit_options": {
            "compiler": compiler,
            "linker": compiler,
            "flags": list(JIT_FLAGS),
            "cleanup": False,
            "directory": str(directory),
        },
        "jit_serialize": "link",
        "jit_name": jit_name,
        "jit_temp_suffix": False,
        "jit_cleanup": False,
    }


def compiled_function(
    given: ca.Function, compiler: str, directory: Path, jit_name: str
) -> ca.Function:
    """`given` (an SX Function) compiled: nlpsol compiles the functions it generates, not the
    ones it is given (the horizon's `hess_lag`)."""
    inputs = given.sx_in()
    return ca.Function(
        given.name(),
        inputs,
        given.call(inputs),
        given.name_in(),
        given.name_out(),
        jit_options(compiler, directory, jit_name),
    )


def nlp_function(name: str, nlp: dict[str, Any]) -> ca.Function:
    """The NLP {"x", "p", "f", "g"} as one Function (x, p) -> (f, g): what a child compiles and
    what the key hashes."""
    return ca.Function(name, [nlp["x"], nlp["p"]], [nlp["f"], nlp["g"]], ["x", "p"], ["f", "g"])


def split_options(options: dict[str, Any]) -> tuple[dict[str, Any], dict[str, ca.Function]]:
    """nlpsol's options as (the JSON-able ones, the Functions among them: a given derivative
    such as the horizon's `hess_lag`)."""
    functions = {k: v for k, v in options.items() if isinstance(v, ca.Function)}
    return {k: v for k, v in options.items() if k not in functions}, functions


def problem_key(name: str, function: ca.Function, options: dict[str, Any]) -> str:
    """sha256 (hex) of everything the compiled solver depends on (a Function among the options
    by its serialized self)."""
    plain, functions = split_options(options)
    digest = hashlib.sha256()
    header = {
        "format": FORMAT,
        "casadi": ca.CasadiMeta.version(),
        "name": name,
        "flags": JIT_FLAGS,
        "options": plain,
        "functions": sorted(functions),
    }
    digest.update(json.dumps(header, sort_keys=True, default=str).encode())
    digest.update(function.serialize().encode())
    for option in sorted(functions):
        digest.update(functions[option].serialize().encode())
    return digest.hexdigest()


def compile_solver(
    name: str, function: ca.Function, options: dict[str, Any], compiler: str, out: Path
) -> None:
    """Build the solver of `function` with its functions compiled, its shared object in the
    directory `out` without its suffix, and save it to `out` (written to a temporary file
    first, then renamed: a reader never sees half a file). Changes the working directory
    (CasADi writes its C source there): the child process's job only."""
    binary_dir = out.with_suffix("")
    binary_dir.mkdir(parents=True, exist_ok=True)
    os.chdir(binary_dir)
    plain, given = split_options(options)
    compiled = {k: compiled_function(f, compiler, binary_dir, k) for k, f in given.items()}
    options = {**plain, **compiled, **jit_options(compiler, binary_dir)}
    solver = ca.nlpsol(name, "ipopt", function, options)
    for source in [*binary_dir.glob("*.c"), *binary_dir.glob("*.o")]:
        source.unlink(missing_ok=True)
    partial = binary_dir / "solver.partial"
    solver.save(str(partial))
    os.replace(partial, out)


class UpgradingSolver:
    """The interpreted solver until the compiled one is in the cache, then the compiled one
    (checked at each call, which the NLP makes under its solve lock). upgrade: what gives the
    compiled solver once the job is done (None: it stays interpreted)."""

    def __init__(
        self, plain: NlpSolver, job: CompileJob, upgrade: Callable[[], NlpSolver | None]
    ) -> None:
        self._current = plain
        self._job: CompileJob | None = job
        self._upgrade_to = upgrade
        self._loaded = False

    @property
    def compiled(self) -> bool:
        """True once the compiled solver is the one that solves."""
        return self._loaded

    @property
    def current(self) -> NlpSolver:
        """The solver that solves now (the interpreted one until the upgrade)."""
        return self._current

    @property
    def job(self) -> CompileJob | None:
        """The compile it waits for (None once it has upgraded or given up)."""
        return self._job

    def _upgrade(self) -> None:
        job = self._job
        if job is None or not job.done.is_set():
            return
        self._job = None
        loaded = self._upgrade_to()
        if loaded is not None:
            self._current = loaded
            self._loaded = True

    def wait(self, timeout_s: float) -> bool:
        """Wait for the compile (tests, `isac-mission compile`); True once the compiled solver is
        in use."""
        job = self._job
        if job is not None:
            job.done.wait(timeout_s)
        self._upgrade()
        return self._loaded

    def __call__(self, **arguments: Any) -> Any:
        self._upgrade()
        return self._current(**arguments)

    def stats(self) -> Any:
        return self._current.stats()


@dataclass
class CompileJob:
    """One compile for the background worker: the NLP's Function, options, target file."""

    name: str
    function: ca.Function
    options: dict[str, Any]
    path: Path
    done: threading.Event = field(default_factory=threading.Event)


@dataclass
class CompiledNlpCache:
    """An IpoptFactory that loads compiled solvers from `directory` and compiles missing ones
    (module docstring). `events` lists what it did, one line each, for logs and tests."""

    directory: Path = field(default_factory=default_cache_dir)
    compile: CompileMode = "background"
    compiler: str | None = field(default_factory=find_compiler)
    events: list[str] = field(default_factory=list)

    def __post_init__(self) -> None:
        # The compiled solvers this cache loaded, by solver: their file's name.
        self._compiled: weakref.WeakKeyDictionary[Any, str] = weakref.WeakKeyDictionary()
        self._queue: queue.Queue[CompileJob] = queue.Queue()
        self._worker: threading.Thread | None = None
        self._child: subprocess.Popen[bytes] | None = None
        self._lock = threading.Lock()

    def path(self, name: str, key: str) -> Path:
        return self.directory / f"{name}-{key[:32]}.casadi"

    def __call__(
        self,
        name: str,
        nlp: dict[str, Any],
        options: dict[str, Any],
        like: NlpSolver | None = None,
    ) -> NlpSolver:
        """The compiled solver of `nlp` from the cache, else an interpreted one (module doc).
        like: a solver of the same nlp (other options) that this factory returned. A compiled
        one (or one waiting for its compile) gives its compiled derivatives, so one compile
        serves both; an interpreted one its interpreted derivatives
        (nlp_model.shared_derivatives)."""
        if isinstance(like, UpgradingSolver) and like.job is not None:
            job, cold = like.job, like

            def upgrade() -> NlpSolver | None:
                return plain_ipopt(name, nlp, options, cold.current) if cold.wait(0) else None

            self._say(f"{name}: interpreted until {job.path.name} is compiled (shares it)")
            return UpgradingSolver(plain_ipopt(name, nlp, options, like.current), job, upgrade)
        if isinstance(like, UpgradingSolver):
            like = like.current
        if like is not None and like in self._compiled:
            self._say(f"{name}: shares the compiled derivatives of {self._compiled[like]}")
            return plain_ipopt(name, nlp, options, like)
        function = nlp_function(name, nlp)
        path = self.path(name, problem_key(name, function, options))
        loaded = self.load(path)
        if loaded is not None:
            return loaded
        if self.compiler is None or self.compile == "never":
            why = "no C compiler" if self.compiler is None else "compiling is off"
            self._say(f"{name}: interpreted ({why}; {path.name} not in the cache)")
            return plain_ipopt(name, nlp, options, like)
        job = CompileJob(name, function, options, path)
        self._submit(job)
        if self.compile == "now":
            job.done.wait()
            compiled = self.load(path)
            return compiled if compiled is not None else plain_ipopt(name, nlp, options, like)
        self._say(f"{name}: interpreted until {path.name} is compiled (in the background)")
        return UpgradingSolver(plain_ipopt(name, nlp, options, like), job, lambda: self.load(path))

    def load(self, path: Path) -> NlpSolver | None:
        """The compiled solver in `path`, or None (absent; a file that does not load is removed,
        and said)."""
        if not path.exists():
            return None
        try:
            solver: NlpSolver = ca.Function.load(str(path))
        except RuntimeError as err:
            self._say(f"{path.name}: could not be loaded ({str(err).splitlines()[0]}); removed")
            path.unlink(missing_ok=True)
            return None
        self._say(f"{path.stem}: compiled, loaded from the cache")
        self._compiled[solver] = path.name
        return solver

    def _say(self, line: str) -> None:
        self.events.append(line)
        LOG.info("%s", line)

    def _submit(self, job: CompileJob) -> None:
        with self._lock:
            self._queue.put(job)
            if self._worker is None:
                self._worker = threading.Thread(target=self._work, name="nlp-compile", daemon=True)
                self._worker.start()
                atexit.register(self.stop)

    def _work(self) -> None:
        while True:
            job = self._queue.get()
            try:
                self._compile_in_child(job)
            finally:
                job.done.set()

    def _compile_in_child(self, job: CompileJob) -> None:
        """Compile `job` in a niced child process (CasADi holds no Python lock there, and a
        crash of the compiler cannot take the service down)."""
        assert self.compiler is not None
        self.directory.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryDirectory(dir=self.directory) as work:
            function_file = Path(work) / "nlp.casadi"
            job.function.save(str(function_file))
            plain, functions = split_options(job.options)
            function_files = {option: str(Path(work) / f"{option}.casadi") for option in functions}
            for option, given in functions.items():
                given.save(function_files[option])
            command = [
                sys.executable,
                "-m",
                "isac_mission.nlp_cache",
                job.name,
                str(function_file),
                json.dumps({"options": plain, "functions": function_files}),
                self.compiler,
                str(job.path),
            ]
            started = time.perf_counter()
            child = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
            with self._lock:
                self._child = child
            _, err = child.communicate()
            with self._lock:
                self._child = None
        if child.returncode == 0 and job.path.exists():
            self._say(f"{job.name}: compiled in {time.perf_counter() - started:.1f} s")
        else:
            last = err.decode(errors="replace").strip().splitlines()[-1:] or ["no output"]
            why = f"compiler exited with {child.returncode}: {last[0]}"
            self._say(f"{job.name}: not compiled ({why}); stays interpreted")

    def stop(self) -> None:
        """Stop a running compile (at exit: a child must not outlive the service)."""
        with self._lock:
            child = self._child
        if child is not None and child.poll() is None:
            child.terminate()


def _main(argv: list[str]) -> int:
    """The child: NAME NLP_FILE OPTIONS_JSON COMPILER OUT (OPTIONS_JSON: {"options": nlpsol's
    JSON-able options, "functions": {option: the file of a Function-valued one}})."""
    name, function_file, options_json, compiler, out = argv
    os.nice(10)
    function = ca.Function.load(function_file)
    given = json.loads(options_json)
    options = given["options"]
    options.update({k: ca.Function.load(path) for k, path in given["functions"].items()})
    compile_solver(name, function, options, compiler, Path(out))
    return 0


if __name__ == "__main__":
    sys.exit(_main(sys.argv[1:]))
