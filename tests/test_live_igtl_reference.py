"""The OpenIGTLink endpoint against a client on the reference C++ library (tests/igtl_client/client.cxx).

The client connects, sends a TRANSFORM, GET_CAPABIL, GET_STATUS and
GET_POLYDATA, and prints every message it receives with the library's own
CRC check.  Skipped where the library (Debian ``libopenigtlink-dev``) or a
C++ compiler is missing; ``CUTKIT_IGTL_CLIENT`` may name a client built
beforehand (.ci/run builds one).
"""

import os
import shutil
import socket
import subprocess
import time
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("pyigtl")

from cutkit.live import LiveFrame  # noqa: E402

HERE = Path(__file__).resolve().parent
#: The package's CMake config: where build.sh reads the include and library paths.
CONFIG = Path(os.environ.get("OPENIGTLINK_CONFIG", "/usr/lib/openigtlink/OpenIGTLinkConfig.cmake"))
#: Longest the client may run (s): it ends as soon as its last query is answered.
RUN_S = 120


@pytest.fixture(scope="module")
def client_binary(tmp_path_factory):
    built = os.environ.get("CUTKIT_IGTL_CLIENT")
    if built and Path(built).is_file():
        return built
    if not CONFIG.is_file():
        pytest.skip("needs the reference OpenIGTLink library: apt-get install libopenigtlink-dev")
    if shutil.which(os.environ.get("CXX", "c++")) is None:
        pytest.skip("needs a C++ compiler (c++ or $CXX) to build tests/igtl_client/client.cxx")
    out = tmp_path_factory.mktemp("igtl_client") / "igtl_client"
    res = subprocess.run(["bash", str(HERE / "igtl_client" / "build.sh"), str(out)], capture_output=True, text=True,
                         timeout=600)
    assert res.returncode == 0, res.stderr[-3000:]
    return str(out)


def _fields(line):
    """``MSG TYPE NAME k=v k=v ...`` as (type, name, {k: v})."""
    parts = line.split(" ")
    rest, out, key = parts[3:], {}, None
    for p in rest:
        if "=" in p and p.split("=", 1)[0].isidentifier():
            key, value = p.split("=", 1)
            out[key] = value
        elif key is not None:
            out[key] += " " + p
    return parts[1], parts[2], out


def test_the_reference_library_client_reads_every_reply(client_binary):
    from cutkit.live.igtl import IGTLEndpoint, IGTLPolyDataView

    ep = IGTLEndpoint(0)
    view = IGTLPolyDataView(endpoint=ep, max_rate_hz=1000.0)
    pts = np.array([[0, 0, 0], [10, 0, 0], [0, 10, 0], [0, 0, 10]], np.float64)
    faces = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]], np.int64)
    frame = LiveFrame(points=pts, boundary_faces=faces, cut_faces=faces[:1], tip=np.array([1.0, 2.0, 3.0]),
                      a=np.array([0.0, 0.0, -1.0]), n=np.array([1.0, 0.0, 0.0]))
    other = socket.create_connection(("127.0.0.1", ep.port), timeout=RUN_S)  # another client, already there
    try:
        view.min_period = 0.0
        t_end = time.monotonic() + RUN_S
        while not ep.connected and time.monotonic() < t_end:
            time.sleep(0.005)
        view.show(frame)  # the surfaces exist before the reference client comes: it gets them on connect
        res = subprocess.run([client_binary, "127.0.0.1", str(ep.port)], capture_output=True, text=True,
                             timeout=RUN_S)
        assert res.returncode == 0, res.stderr
        lines = res.stdout.splitlines()
        assert lines[-1] == "DONE", res.stdout
        msgs = [_fields(x) for x in lines if x.startswith("MSG ")]
        assert all(f["crc"] == "ok" for _, _, f in msgs), res.stdout  # the library's own CRC check
        kind, name, f = msgs[0]
        assert (kind, name, f["code"]) == ("STATUS", "Cutkit", "1"), res.stdout  # STATUS OK on connect
        caps = [f for k, _, f in msgs if k == "CAPABILITY"]
        assert len(caps) == 1 and {"TRANSFORM", "POLYDATA", "GET_TRANS", "GET_POLYDATA", "GET_STATUS",
                                   "GET_CAPABIL"} <= set(caps[0]["types"].split(","))
        statuses = [f for k, _, f in msgs if k == "STATUS"]
        assert len(statuses) == 3 and all(f["code"] == "1" for f in statuses)  # connect, GET_STATUS, ClientDone
        tissue = [f for k, n, f in msgs if (k, n) == ("POLYDATA", "CutkitTissue")]
        assert len(tissue) == 2  # on connect, and the GET_POLYDATA reply
        attrs = {a.split(":")[0]: a.split(":")[1:] for a in tissue[-1]["attributes"].split(";")}
        assert tissue[-1]["points"] == "4" and tissue[-1]["polygons"] == "4"
        assert attrs["Normals"][:3] == ["POINT_NORMAL", "4", "3"]
        assert attrs["Colors"][:3] == ["POINT_RGBA", "4", "4"]
        blade = [f for k, n, f in msgs if (k, n) == ("TRANSFORM", "CutkitBlade")]
        assert blade and blade[0]["translation"] == "-1,-2,3"  # the tip, LPS -> RAS
        # and the endpoint took the client's TRANSFORM
        msg = ep.take("ScalpelToReference")
        assert msg is not None
        np.testing.assert_allclose(msg.matrix[:3, 3], (1.0, 2.0, 3.0))
    finally:
        other.close()
        view.close()
        ep.close()
