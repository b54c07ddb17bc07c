"""A distband-server process for the Python tests: 127.0.0.1, any free port (read from its "(port N," listening line).

The binary is $DISTBAND_SERVER_BINARY, which CTest sets (tests/CMakeLists.txt).
"""
import os
import re
import subprocess
import threading


class ServerProcess:
    def __init__(self, *args):
        server = os.environ["DISTBAND_SERVER_BINARY"]
        self.proc = subprocess.Popen([server, "--listen", "127.0.0.1:0", "--threads", "2", *args],
                                     stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        self.lines = []
        self._port = threading.Event()
        self.port = None
        threading.Thread(target=self._read, daemon=True).start()
        if not self._port.wait(15):
            self.stop()
            raise RuntimeError("distband-server did not report its port:\n" + self.log())

    def _read(self):
        for line in self.proc.stdout:
            self.lines.append(line)
            m = re.search(r"\(port (\d+),", line)
            if m and self.port is None:
                self.port = int(m.group(1))
                self._port.set()

    def log(self):
        return "".join(self.lines)

    @property
    def target(self):
        return f"127.0.0.1:{self.port}"

    def stop(self):
        self.proc.terminate()
        try:
            self.proc.wait(20)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()
