"""A Dask cluster of separate processes on this machine, loopback only: a `dask scheduler` and
N `dask worker` processes (each a nanny and its worker, one thread), as on a real farm but
on one machine. The farm tests and scripts/bench_farm.py start theirs with it; a worker may
be bound to some CPUs (as a farm gives each task its cores).
"""

import os
import subprocess
import sys
import time


def stop_processes(procs, timeout=30):
    """Terminates `procs` (subprocess.Popen), waits for each, kills the ones that linger."""
    for p in procs:
        p.terminate()
    for p in procs:
        try:
            p.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            p.kill()
            p.wait()


def absolute_pythonpath():
    """Makes $PYTHONPATH's entries absolute (build/python as given on a command line), so
    that processes started in other folders find the same modules."""
    os.environ["PYTHONPATH"] = os.pathsep.join(
        os.path.abspath(p) for p in os.environ.get("PYTHONPATH", "").split(os.pathsep) if p)


class Loopback:
    """Start with Loopback(folder, workers, cpus=None).start(); `address`, `client`; stop()
    ends every process. cpus: None, or one CPU list per worker ("0", "1", "0,1")."""

    def __init__(self, folder, workers=2, cpus=None, python=sys.executable):
        self.folder, self.workers, self.cpus = str(folder), workers, cpus
        self.dask = os.path.join(os.path.dirname(python), "dask")
        self.procs, self.client, self.address = [], None, None
        self.log = None

    def start(self, timeout=120):
        from distributed import Client
        sfile = os.path.join(self.folder, "scheduler-%d.json" % os.getpid())
        if os.path.exists(sfile):
            os.remove(sfile)
        self.log = open(os.path.join(self.folder, "cluster.log"), "ab")
        self._spawn([self.dask, "scheduler", "--host", "127.0.0.1", "--port", "0",
                     "--no-dashboard", "--scheduler-file", sfile])
        t0 = time.time()
        while not os.path.isfile(sfile):
            if time.time() - t0 > timeout or self.procs[0].poll() is not None:
                self.stop()
                raise RuntimeError("the scheduler did not start (see %s)" % self.log.name)
            time.sleep(0.1)
        try:
            for i in range(self.workers):
                cmd = [self.dask, "worker", "--scheduler-file", sfile, "--nthreads", "1",
                       "--host", "127.0.0.1", "--no-dashboard", "--name", "worker-%d" % i]
                if self.cpus:
                    cmd = ["taskset", "-c", self.cpus[i]] + cmd
                self._spawn(cmd)
            self.client = Client(scheduler_file=sfile, timeout="60s")
            self.client.wait_for_workers(self.workers, timeout=timeout)
            self.address = self.client.scheduler.address
        except BaseException:
            self.stop()
            raise
        return self

    def _spawn(self, cmd):
        self.procs.append(subprocess.Popen(cmd, stdout=self.log, stderr=self.log,
                                           stdin=subprocess.DEVNULL, cwd=self.folder))

    def stop(self):
        if self.client is not None:
            self.client.close()
            self.client = None
        stop_processes(self.procs[::-1])
        self.procs = []
        if self.log:
            self.log.close()
            self.log = None
