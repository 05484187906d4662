"""A single-node Slurm cluster in a folder, for the farm tests: a MUNGE daemon with its own key
and socket, slurmctld and slurmd on free loopback ports, every file (configuration, state,
spool, logs) inside the folder and nothing of the machine's own configuration used or
changed. Needs Debian's slurmctld, slurmd, slurm-client and munge (scripts/setup.sh) and
root (slurmd starts jobs as their user).

    with SlurmNode(folder) as node:     # node.env: os.environ with SLURM_CONF set
        subprocess.run(["sbatch", ...], env=node.env)
        node.wait_idle(timeout)
"""

import os
import shutil
import socket
import subprocess
import time

from deformkit_farm.loopback import stop_processes  # test_farm.py puts scripts/ on the path

TOOLS = ("munged", "slurmctld", "slurmd", "sbatch", "squeue", "sinfo")


def missing_tools():
    """The programs this needs that the machine lacks, and why it cannot run ([] if it can)."""
    why = [t for t in TOOLS if shutil.which(t) is None]
    if hasattr(os, "geteuid") and os.geteuid() != 0:
        why.append("root (slurmd starts jobs as their user)")
    return why


def _free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class SlurmNode:
    def __init__(self, folder, timeout=60):
        self.dir = os.path.join(str(folder), "slurm")
        self.timeout = timeout
        self.procs = []
        self.env = None

    def _path(self, name):
        return os.path.join(self.dir, name)

    def __enter__(self):
        os.makedirs(self._path("state"), exist_ok=True)
        os.makedirs(self._path("spool"), exist_ok=True)
        os.chmod(self.dir, 0o755)
        key = self._path("munge.key")
        with open(key, "wb") as f:
            f.write(os.urandom(128))
        os.chmod(key, 0o400)
        sock = self._path("munge.sock")
        host = socket.gethostname().split(".")[0]
        cpus = len(os.sched_getaffinity(0))
        conf = self._path("slurm.conf")
        with open(conf, "w") as f:
            f.write("\n".join([
                "ClusterName=deformkit-test",
                "SlurmctldHost=%s(127.0.0.1)" % host,
                "SlurmctldPort=%d" % _free_port(),
                "SlurmdPort=%d" % _free_port(),
                "SlurmUser=root", "SlurmdUser=root",
                "AuthType=auth/munge", "CredType=cred/munge",
                "AuthInfo=socket=%s" % sock,
                "StateSaveLocation=%s" % self._path("state"),
                "SlurmdSpoolDir=%s" % self._path("spool"),
                "SlurmctldPidFile=%s" % self._path("slurmctld.pid"),
                "SlurmdPidFile=%s" % self._path("slurmd.pid"),
                "SlurmctldLogFile=%s" % self._path("slurmctld.log"),
                "SlurmdLogFile=%s" % self._path("slurmd.log"),
                "ProctrackType=proctrack/linuxproc", "TaskPlugin=task/none",
                "JobAcctGatherType=jobacct_gather/none",
                "AccountingStorageType=accounting_storage/none", "JobCompType=jobcomp/none",
                "SchedulerType=sched/builtin", "SelectType=select/cons_tres",
                "SelectTypeParameters=CR_CPU", "MpiDefault=none", "ReturnToService=2",
                "NodeName=%s NodeAddr=127.0.0.1 CPUs=%d State=UNKNOWN" % (host, cpus),
                "PartitionName=local Nodes=%s Default=YES MaxTime=INFINITE State=UP" % host,
                ""]))
        self.env = dict(os.environ, SLURM_CONF=conf)
        log = open(self._path("daemons.log"), "ab")
        try:
            self._start(["munged", "-F", "--force", "-S", sock, "--key-file=%s" % key,
                         "--log-file=%s" % self._path("munged.log"),
                         "--pid-file=%s" % self._path("munged.pid"),
                         "--seed-file=%s" % self._path("munged.seed")], log)
            self._wait(lambda: os.path.exists(sock), "munged")
            self._start(["slurmctld", "-D", "-i"], log)
            self._wait(lambda: self._run(["sinfo", "-h"]).returncode == 0, "slurmctld")
            self._start(["slurmd", "-D"], log)
            self._wait(lambda: "idle" in self._run(["sinfo", "-h", "-o", "%T"]).stdout,
                       "slurmd (the node idle)")
        except BaseException:
            self.__exit__(None, None, None)
            raise
        finally:
            log.close()
        return self

    def _start(self, cmd, log):
        self.procs.append(subprocess.Popen(cmd, stdout=log, stderr=log, env=self.env,
                                           stdin=subprocess.DEVNULL, cwd=self.dir))

    def _run(self, cmd):
        return subprocess.run(cmd, env=self.env, capture_output=True, text=True, timeout=30)

    def _wait(self, ready, what):
        t0 = time.time()
        while not ready():
            dead = [p.args[0] for p in self.procs if p.poll() is not None]
            if dead or time.time() - t0 > self.timeout:
                raise RuntimeError("%s did not start (%s); see %s"
                                   % (what, "exited: %s" % dead if dead else "timed out",
                                      self.dir))
            time.sleep(0.2)

    def wait_idle(self, timeout):
        """Waits until no job is queued or running; False on timeout."""
        t0 = time.time()
        while time.time() - t0 < timeout:
            if not self._run(["squeue", "-h"]).stdout.strip():
                return True
            time.sleep(0.5)
        return False

    def __exit__(self, *exc):
        if self.env is not None and shutil.which("scancel"):
            subprocess.run(["scancel", "--user", "root"], env=self.env, capture_output=True)
        stop_processes(self.procs[::-1], timeout=20)
        self.procs = []
        return False
