#!/usr/bin/env python3
"""A real single-node SLURM cluster on this machine, for testing the workflow's SLURM profile.

Starts, from Debian's packages (``slurm-wlm``, ``slurmdbd``, ``munge``, ``mariadb-server``; installed
with ``apt-get`` when missing, which needs root), with every file under one state folder:

====================  ==================================================================  =========
daemon                what for                                                            listens
====================  ==================================================================  =========
``munged``            authentication between SLURM components                             a socket in the state folder
``mariadbd``          the accounting database behind ``slurmdbd``                         127.0.0.1:<port>
``slurmdbd``          job accounting, so that ``sacct`` (the executor plugin's status      127.0.0.1:<port>
                      query) and ``sacctmgr`` (its account check) work
``slurmctld``         the controller: one partition, one node                             127.0.0.1:<port>
``slurmd``            the node: this machine's CPUs and memory (``slurmd -C``)            127.0.0.1:<port>
====================  ==================================================================  =========

``slurm.conf`` is minimal: no cgroups (``ProctrackType=proctrack/linuxproc``, ``TaskPlugin=task/none``),
``select/cons_tres`` with ``CR_Core_Memory`` (jobs are placed by CPUs and ``--mem``), accounting through
``slurmdbd`` with ``AccountingStorageEnforce=associations`` (a job needs a valid account, as on most
clusters), ``jobacct_gather/linux`` (``MaxRSS`` in ``sacct``). Ports are free ones from 27000-29999
(tried in a random order), all daemons bind 127.0.0.1 only, so two harnesses can coexist.

The cluster gets an account (default ``becos-test``) holding the current user, and one default
partition (default ``becos``). Clients need ``SLURM_CONF=<state>/slurm.conf`` (:meth:`SlurmHarness.env`);
``<state>/env.sh`` exports it. Because ``snakemake-executor-plugin-slurm-jobstep`` removes every
``SLURM_*`` variable (``SLURM_CONF`` too) before the ``srun`` inside a job, that ``srun`` reads the
default ``/etc/slurm/slurm.conf``: the harness writes a copy there (marked with a header line) unless
one exists that it did not write, and removes it at :meth:`SlurmHarness.stop`.

Command line (root)::

    python3 cluster/slurm_harness.py start --state /tmp/becos-slurm   # install if needed, start, check
    . /tmp/becos-slurm/env.sh                                          # SLURM_CONF for sinfo, sbatch ...
    python3 cluster/slurm_harness.py status --state /tmp/becos-slurm   # sinfo + sacct
    python3 cluster/slurm_harness.py stop --state /tmp/becos-slurm     # cancel jobs, stop every daemon

From Python (``tests/test_slurm.py``)::

    harness = SlurmHarness(tmp_dir)
    harness.start()              # raises HarnessError(command, output) when a daemon cannot run here
    env = {**os.environ, **harness.env()}
    ...
    harness.stop()

Only the standard library is used, so the system ``python3`` runs it.
"""

from __future__ import annotations

import argparse
import getpass
import json
import os
import random
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

PACKAGES = ["slurm-wlm", "slurmdbd", "munge", "mariadb-server"]
# the executables each package provides
BINARIES = {
    "munged": "munge",
    "munge": "munge",
    "mariadbd": "mariadb-server",
    "mariadb-install-db": "mariadb-server",
    "mariadb": "mariadb-server",
    "mariadb-admin": "mariadb-server",
    "slurmdbd": "slurmdbd",
    "slurmctld": "slurm-wlm",
    "slurmd": "slurm-wlm",
    "sinfo": "slurm-wlm",
    "sacct": "slurm-wlm",
    "sacctmgr": "slurm-wlm",
    "sbatch": "slurm-wlm",
    "srun": "slurm-wlm",
    "scontrol": "slurm-wlm",
    "scancel": "slurm-wlm",
    "squeue": "slurm-wlm",
}
ETC_SLURM_CONF = Path("/etc/slurm/slurm.conf")
MARKER = "# written by becos cluster/slurm_harness.py"
DAEMONS = ("slurmd", "slurmctld", "slurmdbd", "mariadbd", "munged")  # stop order


class HarnessError(RuntimeError):
    """A step that failed: the exact command, its output, and the state folder (logs)."""

    def __init__(self, step: str, command: list[str] | str, output: str, state: Path | None = None):
        self.step, self.output, self.state = step, output.strip(), state
        self.command = command if isinstance(command, str) else " ".join(command)
        logs = f" (logs: {state}/log)" if state else ""
        super().__init__(f"{step} failed{logs}\n$ {self.command}\n{self.output}")


def _write(path: Path, text: str, mode: int = 0o644) -> None:
    """Write ``text`` to ``path`` atomically (temporary file beside it, then rename) with ``mode``."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "w") as fh:
            fh.write(text)
        os.chmod(tmp, mode)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def _free_ports(n: int, low: int = 27000, high: int = 30000) -> list[int]:
    """``n`` TCP ports in [low, high) that 127.0.0.1 can bind now, in a random order."""
    candidates = list(range(low, high))
    random.shuffle(candidates)
    ports = []
    for port in candidates:
        with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
            try:
                s.bind(("127.0.0.1", port))
            except OSError:
                continue
        ports.append(port)
        if len(ports) == n:
            return ports
    raise HarnessError("choosing ports", f"bind 127.0.0.1:{low}-{high}", "no free ports")


def missing_binaries() -> dict[str, str]:
    """Executables the harness needs that are not on PATH (or in /usr/sbin), with their package."""
    path = os.pathsep.join([os.environ.get("PATH", ""), "/usr/sbin", "/sbin"])
    return {b: p for b, p in BINARIES.items() if shutil.which(b, path=path) is None}


def install_packages(log=print) -> float:
    """``apt-get install`` the packages of missing executables; returns seconds spent (0 if none).

    Services are not started by the packages' scripts (a temporary ``/usr/sbin/policy-rc.d`` answers
    101 when none exists). Raises :class:`HarnessError` when not root or when apt-get fails.
    """
    missing = missing_binaries()
    if not missing:
        return 0.0
    packages = sorted(set(missing.values()))
    if os.geteuid() != 0:
        raise HarnessError(
            "installing SLURM",
            f"apt-get install -y {' '.join(packages)}",
            f"missing {', '.join(sorted(missing))} and not root: install {' '.join(packages)} "
            "(Debian/Ubuntu) as root, then rerun",
        )
    if shutil.which("apt-get") is None:
        raise HarnessError(
            "installing SLURM",
            f"apt-get install -y {' '.join(packages)}",
            f"missing {', '.join(sorted(missing))} and no apt-get: install SLURM (slurmctld, slurmd, "
            "slurmdbd, client commands), munge and MariaDB with this system's package manager",
        )
    start = time.perf_counter()
    policy = Path("/usr/sbin/policy-rc.d")
    own_policy = not policy.exists()
    if own_policy:
        _write(policy, "#!/bin/sh\n# becos slurm harness: no service starts during apt-get install\nexit 101\n", 0o755)
    env = dict(os.environ, DEBIAN_FRONTEND="noninteractive")
    try:
        install = ["apt-get", "install", "-y", "-q", "--no-install-recommends", *PACKAGES]
        result = subprocess.run(install, capture_output=True, text=True, env=env)
        if result.returncode != 0:  # package lists may be missing or stale on a fresh machine
            log("$ apt-get update -q")
            update = subprocess.run(["apt-get", "update", "-q"], capture_output=True, text=True, env=env)
            if update.returncode != 0:
                raise HarnessError("apt-get update", "apt-get update -q", update.stdout[-2000:] + update.stderr[-3000:])
            result = subprocess.run(install, capture_output=True, text=True, env=env)
        log(f"$ {' '.join(install)}")
        if result.returncode != 0:
            raise HarnessError("apt-get install", install, result.stdout[-2000:] + result.stderr[-3000:])
    finally:
        if own_policy:
            policy.unlink(missing_ok=True)
    seconds = time.perf_counter() - start
    still = missing_binaries()
    if still:
        raise HarnessError(
            "apt-get install",
            "apt-get install -y " + " ".join(PACKAGES),
            f"installed, but still missing: {', '.join(sorted(still))}",
        )
    log(f"installed {' '.join(PACKAGES)} in {seconds:.1f} s")
    return seconds


def node_hardware() -> dict[str, int]:
    """CPUs, sockets, cores per socket, threads per core and RealMemory (MiB) of this machine, from ``slurmd -C``."""
    out = subprocess.run(["slurmd", "-C"], capture_output=True, text=True)
    if out.returncode != 0:
        raise HarnessError("reading the node's hardware", "slurmd -C", out.stdout + out.stderr)
    fields = dict(kv.split("=", 1) for kv in out.stdout.split() if "=" in kv)
    keys = ("CPUs", "Boards", "SocketsPerBoard", "CoresPerSocket", "ThreadsPerCore", "RealMemory")
    return {k: int(fields[k]) for k in keys}


class SlurmHarness:
    """One single-node SLURM cluster with accounting, all state under ``state``.

    ``cluster``, ``account`` and ``partition`` name the cluster, the account (holding the current
    user) and the one (default) partition. ``etc_conf``: write ``/etc/slurm/slurm.conf`` (see the
    module docstring); without it, ``srun`` inside a job of the SLURM executor plugin cannot find the
    cluster. ``log``: called with every line of the harness log (also kept in :attr:`lines` and
    ``<state>/harness.log``).
    """

    def __init__(
        self,
        state: str | Path,
        cluster: str = "becos",
        account: str = "becos-test",
        partition: str = "becos",
        etc_conf: bool = True,
        log=None,
    ):
        self.state = Path(state).resolve()
        self.cluster, self.account, self.partition = cluster, account, partition
        self.etc_conf = etc_conf
        self.lines: list[str] = []
        self._echo = log
        self.timings: dict[str, float] = {}
        self._mariadb: subprocess.Popen | None = None
        self.conf = self.state / "slurm" / "slurm.conf"

    # -- logging and commands ------------------------------------------------------------------
    def log(self, line: str) -> None:
        stamp = time.strftime("%H:%M:%S")
        new = [f"[{stamp}] {part}" for part in str(line).splitlines() or [""]]
        self.lines.extend(new)
        if self._echo:
            for part in new:
                self._echo(part)
        if self.state.is_dir():
            with open(self.state / "harness.log", "a") as fh:
                fh.write("\n".join(new) + "\n")

    def env(self) -> dict[str, str]:
        """Environment variables a SLURM client needs for this cluster (``SLURM_CONF``)."""
        return {"SLURM_CONF": str(self.conf)}

    def run(self, *cmd: str, check: bool = True, timeout: float = 60, log: bool = False) -> subprocess.CompletedProcess:
        """Run a command with this cluster's environment; raise :class:`HarnessError` on failure if ``check``."""
        env = dict(os.environ, **self.env())
        try:
            result = subprocess.run(list(cmd), capture_output=True, text=True, env=env, timeout=timeout, cwd=self.state)
        except subprocess.TimeoutExpired as e:
            raise HarnessError(
                f"{cmd[0]} (timed out after {timeout:.0f} s)",
                list(cmd),
                f"{e.stdout or ''}{e.stderr or ''}",
                self.state,
            ) from None
        if log:
            self.log(f"$ {' '.join(cmd)}\n{(result.stdout + result.stderr).rstrip()}")
        if check and result.returncode != 0:
            raise HarnessError(
                cmd[0], list(cmd), f"exit {result.returncode}\n{result.stdout}{result.stderr}", self.state
            )
        return result

    def _wait(self, what: str, probe, timeout: float, last_command: list[str], logfile: Path | None = None) -> None:
        """Call ``probe()`` (-> (ok, output)) until ok, at most ``timeout`` seconds."""
        deadline = time.monotonic() + timeout
        output = ""
        while time.monotonic() < deadline:
            ok, output = probe()
            if ok:
                return
            time.sleep(0.5)
        tail = ""
        if logfile and logfile.exists():
            tail = f"\n--- last lines of {logfile}:\n" + "\n".join(
                logfile.read_text(errors="replace").splitlines()[-15:]
            )
        raise HarnessError(f"waiting for {what} ({timeout:.0f} s)", last_command, output + tail, self.state)

    def _start_daemon(self, name: str, cmd: list[str], logfile: Path) -> None:
        """Start a self-daemonising program; a non-zero exit of the launcher is an error with its output."""
        self.log(f"$ {' '.join(cmd)}")
        result = subprocess.run(cmd, capture_output=True, text=True, env=dict(os.environ, **self.env()), cwd=self.state)
        if result.returncode != 0:
            tail = ""
            if logfile.exists():
                tail = (
                    "\n--- " + str(logfile) + ":\n" + "\n".join(logfile.read_text(errors="replace").splitlines()[-15:])
                )
            raise HarnessError(
                f"starting {name}", cmd, f"exit {result.returncode}\n{result.stdout}{result.stderr}{tail}", self.state
            )

    # -- configuration -------------------------------------------------------------------------
    def _paths(self) -> dict[str, Path]:
        s = self.state
        return {
            "munge_run": s / "munge",
            "munge_key_dir": s / "munge-key",
            "munge_socket": s / "munge" / "munge.socket.2",
            "mysql": s / "mysql",
            "slurm": s / "slurm",
            "log": s / "log",
        }

    def _write_configs(self, ports: dict[str, int], hw: dict[str, int]) -> None:
        p = self._paths()
        host = socket.gethostname().split(".")[0]
        self.node = host
        user = getpass.getuser()
        slurm = p["slurm"]
        for sub in ("ctld", "spool"):
            (slurm / sub).mkdir(parents=True, exist_ok=True)
        common = ["AuthType=auth/munge", f"AuthInfo=socket={p['munge_socket']}"]
        dbd = "\n".join(
            [
                MARKER,
                *common,
                "DbdHost=localhost",
                "DbdAddr=127.0.0.1",
                f"DbdPort={ports['slurmdbd']}",
                f"SlurmUser={user}",
                f"PidFile={slurm / 'slurmdbd.pid'}",
                f"LogFile={p['log'] / 'slurmdbd.log'}",
                "DebugLevel=info",
                "StorageType=accounting_storage/mysql",
                "StorageHost=127.0.0.1",
                f"StoragePort={ports['mariadb']}",
                "StorageUser=slurm",
                f"StoragePass={self._db_password}",
                f"StorageLoc={self.cluster}_acct_db",
                "",
            ]
        )
        _write(slurm / "slurmdbd.conf", dbd, 0o600)  # slurmdbd refuses a readable file (password)
        conf = "\n".join(
            [
                MARKER + f" (state {self.state}); removed when the harness stops",
                f"ClusterName={self.cluster}",
                f"SlurmctldHost={host}(127.0.0.1)",
                f"SlurmctldPort={ports['slurmctld']}",
                f"SlurmdPort={ports['slurmd']}",
                *common,
                "CredType=cred/munge",
                # the dbd connection authenticates through this munge socket (slurm.conf(5) AccountingStoragePass)
                f"AccountingStoragePass={p['munge_socket']}",
                f"SlurmUser={user}",
                "SlurmdUser=root",
                f"StateSaveLocation={slurm / 'ctld'}",
                f"SlurmdSpoolDir={slurm / 'spool'}",
                f"SlurmctldPidFile={slurm / 'slurmctld.pid'}",
                f"SlurmdPidFile={slurm / 'slurmd.pid'}",
                f"SlurmctldLogFile={p['log'] / 'slurmctld.log'}",
                f"SlurmdLogFile={p['log'] / 'slurmd.log'}",
                "SlurmctldDebug=info",
                "SlurmdDebug=info",
                "ProctrackType=proctrack/linuxproc",
                "TaskPlugin=task/none",
                "MpiDefault=none",
                "SwitchType=switch/none",
                "ReturnToService=2",
                "SchedulerType=sched/backfill",
                "SelectType=select/cons_tres",
                "SelectTypeParameters=CR_Core_Memory",
                "JobAcctGatherType=jobacct_gather/linux",
                "JobAcctGatherFrequency=task=1",  # MaxRSS of short steps
                "AccountingStorageType=accounting_storage/slurmdbd",
                "AccountingStorageHost=localhost",
                f"AccountingStoragePort={ports['slurmdbd']}",
                "AccountingStorageEnforce=associations",
                "AccountingStoreFlags=job_comment",  # sacct shows the plugin's comment: rule and wildcards
                "JobCompType=jobcomp/none",
                "MailProg=/bin/true",
                "MinJobAge=300",
                "KillWait=10",
                f"NodeName={host} NodeAddr=127.0.0.1 CPUs={hw['CPUs']} Boards={hw['Boards']} "
                f"SocketsPerBoard={hw['SocketsPerBoard']} CoresPerSocket={hw['CoresPerSocket']} "
                f"ThreadsPerCore={hw['ThreadsPerCore']} RealMemory={hw['RealMemory']} State=UNKNOWN",
                f"PartitionName={self.partition} Nodes={host} Default=YES MaxTime=INFINITE State=UP",
                "",
            ]
        )
        _write(self.conf, conf)
        _write(
            self.state / "env.sh",
            f"# source me: the SLURM client environment of this cluster\nexport SLURM_CONF={self.conf}\n",
        )

    def _install_etc_conf(self) -> None:
        if not self.etc_conf:
            return
        self._check_etc_conf()
        _write(ETC_SLURM_CONF, self.conf.read_text())
        self.log(f"wrote {ETC_SLURM_CONF} (copy of {self.conf})")

    def _check_etc_conf(self) -> None:
        """Raise if /etc/slurm/slurm.conf belongs to a real installation or to another running harness."""
        if not self.etc_conf or not ETC_SLURM_CONF.exists():
            return
        lines = ETC_SLURM_CONF.read_text(errors="replace").splitlines()
        if not lines or not lines[0].startswith(MARKER):
            raise HarnessError(
                "writing /etc/slurm/slurm.conf",
                f"cp {self.conf} {ETC_SLURM_CONF}",
                f"{ETC_SLURM_CONF} exists and was not written by this harness (a real SLURM "
                "installation?): the harness will not overwrite it; run it on a machine without "
                "SLURM, or pass etc_conf=False (jobs of the SLURM executor plugin then fail)",
            )
        other = _writer_state(ETC_SLURM_CONF)
        if other is not None and other != self.state:
            pid_file = other / "slurm" / "slurmctld.pid"
            try:
                pid = int(pid_file.read_text().split()[0])
            except (OSError, ValueError, IndexError):
                pid = None
            if pid is not None and _alive(pid):
                raise HarnessError(
                    "writing /etc/slurm/slurm.conf",
                    f"cp {self.conf} {ETC_SLURM_CONF}",
                    f"another harness cluster (state {other}, slurmctld pid {pid}) owns it: stop "
                    f"that one first (slurm_harness.py stop --state {other})",
                )

    def _remove_etc_conf(self) -> None:
        if _writer_state(ETC_SLURM_CONF) == self.state:
            ETC_SLURM_CONF.unlink(missing_ok=True)
            self.log(f"removed {ETC_SLURM_CONF}")

    # -- start / stop --------------------------------------------------------------------------
    def start(self, install: bool = True) -> dict[str, float]:
        """Install missing packages (if ``install``), write the configuration, start the five daemons
        and wait until the node is idle, the account exists and ``srun hostname`` works. Returns the
        seconds per stage (also in :attr:`timings`). Raises :class:`HarnessError` on the first failure
        (the daemons already started stay up: call :meth:`stop`).
        """
        t0 = time.perf_counter()
        self.state.mkdir(parents=True, exist_ok=True)
        os.chmod(self.state, 0o755)  # munged requires execute permission for all on its socket's path
        self.log(f"SLURM harness, state {self.state}")
        if os.geteuid() != 0:
            raise HarnessError(
                "starting the SLURM harness",
                f"id -u -> {os.geteuid()}",
                "slurmd must run as root to start jobs: run the harness (and the test) as root",
            )
        self.timings["install_s"] = install_packages(self.log) if install else 0.0
        still = missing_binaries()
        if still:
            raise HarnessError(
                "finding SLURM",
                "which " + " ".join(sorted(still)),
                f"not installed: {', '.join(sorted(still))} (packages {' '.join(PACKAGES)})",
            )
        self._check_etc_conf()
        t1 = time.perf_counter()
        p = self._paths()
        for key in ("munge_run", "mysql", "slurm", "log"):
            p[key].mkdir(parents=True, exist_ok=True)
            os.chmod(p[key], 0o755)
        p["munge_key_dir"].mkdir(exist_ok=True)
        os.chmod(p["munge_key_dir"], 0o700)
        names = ("mariadb", "slurmdbd", "slurmctld", "slurmd")
        ports = dict(zip(names, _free_ports(len(names))))
        self.ports = ports
        self._db_password = os.urandom(12).hex()
        hw = node_hardware()
        self._write_configs(ports, hw)
        _write(
            self.state / "harness.json",
            json.dumps(
                {
                    "ports": ports,
                    "hardware": hw,
                    "cluster": self.cluster,
                    "account": self.account,
                    "partition": self.partition,
                    "node": self.node,
                },
                indent=1,
            )
            + "\n",
        )
        self.log(f"node {self.node}: {hw}; ports {ports}")
        self._start_munge()
        self._start_mariadb()
        self._start_slurmdbd()
        self._add_associations()
        self._install_etc_conf()
        self._start_slurmctld()
        self._start_slurmd()
        self._smoke_test()
        self.timings["start_s"] = time.perf_counter() - t1
        self.timings["total_s"] = time.perf_counter() - t0
        self.log(f"cluster up in {self.timings['start_s']:.1f} s (install {self.timings['install_s']:.1f} s)")
        return dict(self.timings)

    def _start_munge(self) -> None:
        p = self._paths()
        key = p["munge_key_dir"] / "munge.key"
        if not key.exists():
            _write(key, os.urandom(1024).hex(), 0o400)
        cmd = [
            "munged",
            f"--key-file={key}",
            f"--socket={p['munge_socket']}",
            f"--pid-file={p['munge_run'] / 'munged.pid'}",
            f"--log-file={p['log'] / 'munged.log'}",
            f"--seed-file={p['munge_key_dir'] / 'munged.seed'}",
        ]
        self._start_daemon("munged", cmd, p["log"] / "munged.log")
        check = f"munge -S {p['munge_socket']} -n | unmunge -S {p['munge_socket']}"

        def probe():
            r = subprocess.run(check, shell=True, capture_output=True, text=True)
            return r.returncode == 0 and "Success" in r.stdout, r.stdout + r.stderr

        self._wait("munged", probe, 20, check, p["log"] / "munged.log")
        self.log(f"munged: ok ({check})")

    def _start_mariadb(self) -> None:
        p = self._paths()
        data = p["mysql"] / "data"
        sock = p["mysql"] / "mysqld.sock"
        user = getpass.getuser()
        if not (data / "mysql").is_dir():
            cmd = [
                "mariadb-install-db",
                "--no-defaults",
                f"--user={user}",
                f"--datadir={data}",
                "--auth-root-authentication-method=socket",
                "--skip-test-db",
            ]
            self.log(f"$ {' '.join(cmd)}")
            r = subprocess.run(cmd, capture_output=True, text=True, cwd=self.state)
            if r.returncode != 0:
                raise HarnessError(
                    "initialising the MariaDB data folder", cmd, r.stdout[-3000:] + r.stderr[-3000:], self.state
                )
        cmd = [
            "mariadbd",
            "--no-defaults",
            f"--user={user}",
            f"--datadir={data}",
            f"--socket={sock}",
            f"--port={self.ports['mariadb']}",
            "--bind-address=127.0.0.1",
            "--skip-name-resolve",
            f"--pid-file={p['mysql'] / 'mysqld.pid'}",
            f"--log-error={p['log'] / 'mariadb.log'}",
            "--innodb-buffer-pool-size=128M",
            "--innodb-lock-wait-timeout=900",
            "--skip-log-bin",
        ]
        self.log(f"$ {' '.join(cmd)}")
        with open(p["log"] / "mariadb.out", "ab") as out:
            self._mariadb = subprocess.Popen(
                cmd,
                stdout=out,
                stderr=subprocess.STDOUT,
                stdin=subprocess.DEVNULL,
                start_new_session=True,
                cwd=self.state,
            )
        ping = ["mariadb-admin", "--no-defaults", f"--socket={sock}", "-u", user, "ping"]

        def probe():
            if self._mariadb.poll() is not None:
                raise HarnessError(
                    "starting mariadbd",
                    cmd,
                    f"exited with {self._mariadb.returncode}\n"
                    + (p["log"] / "mariadb.log").read_text(errors="replace")[-3000:],
                    self.state,
                )
            r = subprocess.run(ping, capture_output=True, text=True)
            return r.returncode == 0, r.stdout + r.stderr

        self._wait("mariadbd", probe, 60, ping, p["log"] / "mariadb.log")
        db = f"{self.cluster}_acct_db"
        sql = "; ".join(
            [
                f"CREATE USER IF NOT EXISTS 'slurm'@'127.0.0.1' IDENTIFIED BY '{self._db_password}'",
                f"ALTER USER 'slurm'@'127.0.0.1' IDENTIFIED BY '{self._db_password}'",
                f"CREATE DATABASE IF NOT EXISTS {db}",
                f"GRANT ALL ON {db}.* TO 'slurm'@'127.0.0.1'",
                "FLUSH PRIVILEGES",
            ]
        )
        cmd = ["mariadb", "--no-defaults", f"--socket={sock}", "-u", user, "-e", sql]
        r = subprocess.run(cmd, capture_output=True, text=True)
        if r.returncode != 0:
            raise HarnessError(
                "creating the accounting database user",
                cmd[:-2] + ["-e", "'CREATE USER slurm ...'"],
                r.stdout + r.stderr,
                self.state,
            )
        self.log(f"mariadbd: ok (127.0.0.1:{self.ports['mariadb']}, database {db})")

    def _start_slurmdbd(self) -> None:
        p = self._paths()
        # slurmdbd reads slurmdbd.conf from the folder of $SLURM_CONF
        self._start_daemon("slurmdbd", ["slurmdbd"], p["log"] / "slurmdbd.log")
        cmd = ["sacctmgr", "-n", "-P", "list", "cluster", "format=cluster"]

        def probe():
            r = self.run(*cmd, check=False, timeout=20)
            return r.returncode == 0, r.stdout + r.stderr

        self._wait("slurmdbd", probe, 60, cmd, p["log"] / "slurmdbd.log")
        self.log(f"slurmdbd: ok (127.0.0.1:{self.ports['slurmdbd']})")

    def _add_associations(self) -> None:
        user = getpass.getuser()
        clusters = self.run("sacctmgr", "-n", "-P", "list", "cluster", "format=cluster").stdout.split()
        if self.cluster not in clusters:
            self.run("sacctmgr", "-i", "add", "cluster", self.cluster, log=True)
        accounts = self.run("sacctmgr", "-n", "-P", "list", "account", "format=account").stdout.split()
        if self.account not in accounts:
            self.run(
                "sacctmgr",
                "-i",
                "add",
                "account",
                self.account,
                f"cluster={self.cluster}",
                "Description=becos test account",
                "Organization=becos",
                log=True,
            )
        users = self.run(
            "sacctmgr", "-n", "-P", "list", "association", f"account={self.account}", "format=user"
        ).stdout.split()
        if user not in users:
            self.run(
                "sacctmgr", "-i", "add", "user", user, f"account={self.account}", f"cluster={self.cluster}", log=True
            )

    def _start_slurmctld(self) -> None:
        p = self._paths()
        self._start_daemon("slurmctld", ["slurmctld"], p["log"] / "slurmctld.log")
        cmd = ["scontrol", "ping"]

        def probe():
            r = self.run(*cmd, check=False, timeout=20)
            return r.returncode == 0 and "UP" in r.stdout, r.stdout + r.stderr

        self._wait("slurmctld", probe, 60, cmd, p["log"] / "slurmctld.log")
        self.log(f"slurmctld: ok (127.0.0.1:{self.ports['slurmctld']})")

    def _start_slurmd(self) -> None:
        p = self._paths()
        self._start_daemon("slurmd", ["slurmd"], p["log"] / "slurmd.log")
        cmd = ["sinfo", "-h", "-N", "-n", self.node, "-o", "%t"]

        def probe():
            r = self.run(*cmd, check=False, timeout=20)
            return r.returncode == 0 and r.stdout.strip() == "idle", r.stdout + r.stderr

        self._wait("slurmd (node idle in sinfo)", probe, 60, cmd, p["log"] / "slurmd.log")
        # the controller has registered with slurmdbd once sacctmgr knows its address
        cmd = ["sacctmgr", "-n", "-P", "list", "cluster", self.cluster, "format=cluster,controlhost,controlport"]

        def registered():
            r = self.run(*cmd, check=False, timeout=20)
            fields = r.stdout.strip().split("|")
            return r.returncode == 0 and len(fields) == 3 and fields[1] != "", r.stdout + r.stderr

        self._wait("slurmctld registering with slurmdbd", registered, 60, cmd, p["log"] / "slurmctld.log")
        self.log(f"slurmd: ok (127.0.0.1:{self.ports['slurmd']})")
        self.run("sinfo", log=True)
        self.run(*cmd, log=True)

    def _smoke_test(self) -> None:
        r = self.run(
            "srun", "-A", self.account, "-p", self.partition, "-t", "1", "--mem", "10", "hostname", timeout=60, log=True
        )
        if r.stdout.strip() != socket.gethostname():
            raise HarnessError(
                "srun hostname", "srun hostname", f"printed {r.stdout!r}, expected {socket.gethostname()!r}", self.state
            )
        cmd = ["sinfo", "-h", "-N", "-n", self.node, "-o", "%t"]

        def idle():
            r = self.run(*cmd, check=False, timeout=20)
            return r.returncode == 0 and r.stdout.strip() == "idle", r.stdout + r.stderr

        self._wait("the node to be idle after srun", idle, 60, cmd, self._paths()["log"] / "slurmd.log")
        cmd = ["sacct", "-a", "-X", "-n", "-P", "-S", "now-1days", "--name", "hostname", "-o", "JobID,State,ExitCode"]

        def accounted():
            r = self.run(*cmd, check=False, timeout=20)
            return r.returncode == 0 and "|COMPLETED|0:0" in r.stdout, r.stdout + r.stderr

        self._wait("sacct to list the srun job", accounted, 60, cmd, self._paths()["log"] / "slurmdbd.log")
        self.run(*cmd, log=True)

    def sinfo(self) -> str:
        return self.run("sinfo", "-N", "-o", "%N %P %t %c %m %O", check=False).stdout

    def sacct(
        self,
        fmt: str = "JobID,JobName%40,Account,State,ExitCode,Elapsed,MaxRSS",
        all_steps: bool = False,
        extra: tuple[str, ...] = (),
    ) -> str:
        """``sacct`` of every job of this cluster since the harness started (``-X``: allocations only)."""
        args = ["sacct", "-a", "-S", "now-1days", f"--format={fmt}", *extra]
        if not all_steps:
            args.append("-X")
        r = self.run(*args, check=False)
        return r.stdout + r.stderr

    def jobs(self) -> list[dict[str, str]]:
        """Every job allocation as a dict of ``JobID, JobName, State, ExitCode, Elapsed, Comment``."""
        fields = ["JobID", "JobName", "State", "ExitCode", "Elapsed", "Comment"]
        r = self.run("sacct", "-a", "-X", "-n", "-P", "-S", "now-1days", f"--format={','.join(fields)}")
        return [dict(zip(fields, line.split("|"))) for line in r.stdout.splitlines() if line.strip()]

    def _pid(self, name: str) -> int | None:
        p = self._paths()
        files = {
            "munged": p["munge_run"] / "munged.pid",
            "mariadbd": p["mysql"] / "mysqld.pid",
            "slurmdbd": p["slurm"] / "slurmdbd.pid",
            "slurmctld": p["slurm"] / "slurmctld.pid",
            "slurmd": p["slurm"] / "slurmd.pid",
        }
        try:
            return int(files[name].read_text().split()[0])
        except (OSError, ValueError, IndexError):
            return None

    def stop(self) -> None:
        """Cancel this cluster's jobs, stop its five daemons (by their pid files), remove /etc/slurm/slurm.conf if ours."""
        if self.conf.exists() and shutil.which("scancel"):
            try:
                if self.run("squeue", "-h", "-o", "%i", check=False, timeout=20).stdout.strip():
                    self.run("scancel", "-u", getpass.getuser(), check=False, timeout=20, log=True)
                    deadline = time.monotonic() + 30
                    while (
                        time.monotonic() < deadline
                        and self.run("squeue", "-h", "-o", "%i", check=False, timeout=20).stdout.strip()
                    ):
                        time.sleep(1)
            except HarnessError:
                pass
        for name in DAEMONS:
            pid = self._pid(name)
            if pid is None and name == "mariadbd" and self._mariadb is not None:
                pid = self._mariadb.pid
            if pid is None or not _alive(pid):
                continue
            try:
                os.kill(pid, signal.SIGTERM)
            except ProcessLookupError:
                continue
            deadline = time.monotonic() + 20
            while time.monotonic() < deadline and _alive(pid):
                time.sleep(0.2)
            if _alive(pid):
                os.kill(pid, signal.SIGKILL)
            self.log(f"stopped {name} (pid {pid})")
        if self._mariadb is not None:
            try:
                self._mariadb.wait(timeout=10)
            except subprocess.TimeoutExpired:
                self._mariadb.kill()
        self._remove_etc_conf()


def _writer_state(conf: Path) -> Path | None:
    """The state folder named in the marker line of a harness-written slurm.conf, else None."""
    try:
        first = conf.read_text(errors="replace").splitlines()[0]
    except (OSError, IndexError):
        return None
    if not first.startswith(MARKER) or "(state " not in first:
        return None
    return Path(first.split("(state ", 1)[1].split(")", 1)[0])


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    try:  # a zombie child of ours counts as gone
        with open(f"/proc/{pid}/stat") as fh:
            return fh.read().split(")")[-1].split()[0] != "Z"
    except OSError:
        return True


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("action", choices=["start", "stop", "status"])
    parser.add_argument(
        "--state",
        type=Path,
        default=Path(tempfile.gettempdir()) / "becos-slurm",
        help="folder for configuration, logs and daemon state (default: %(default)s)",
    )
    parser.add_argument("--cluster", default="becos")
    parser.add_argument("--account", default="becos-test")
    parser.add_argument("--partition", default="becos")
    parser.add_argument("--no-install", action="store_true", help="do not apt-get install missing packages")
    args = parser.parse_args(argv)
    harness = SlurmHarness(args.state, args.cluster, args.account, args.partition, log=print)
    if args.action == "start":
        try:
            harness.start(install=not args.no_install)
        except HarnessError as e:
            print(f"error: {e}", file=sys.stderr)
            return 1
        print(f"\nexport SLURM_CONF={harness.conf}    # or: . {args.state}/env.sh")
        print(f"account {args.account}, partition {args.partition}; stop: {sys.argv[0]} stop --state {args.state}")
    elif args.action == "status":
        print(harness.sinfo())
        print(harness.sacct())
    else:
        harness.stop()
    return 0


if __name__ == "__main__":
    sys.exit(main())
