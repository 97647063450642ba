"""scheduler_client on addresses that are not Dask schedulers: a deadline on the whole
client start, and named errors instead of hangs, MemoryError and ValueError tracebacks."""

from __future__ import annotations

import http.server
import socket
import threading

import numpy as np
import pytest

import photogeom as pg
from photogeom.errors import InputError, PhotogeomError

pytest.importorskip("distributed")


@pytest.fixture
def short_deadline(monkeypatch):
    """The code's own connect deadline, short so that each test stays within seconds."""
    monkeypatch.setattr(pg.distributed, "CONNECT_TIMEOUT", 1.5)


@pytest.fixture
def silent_listener():
    """A TCP port that accepts connections and never sends anything."""
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    s.listen(5)
    yield f"tcp://127.0.0.1:{s.getsockname()[1]}"
    s.close()


@pytest.fixture
def banner_server():
    """A TCP port that sends a text banner on connection (like ssh or smtp)."""
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    s.listen(5)
    s.settimeout(0.2)
    stop = threading.Event()

    def serve():
        conns = []
        while not stop.is_set():
            try:
                c, _ = s.accept()
            except OSError:
                continue
            c.sendall(b"SSH-2.0-OpenSSH_9.6 banner text\r\n" * 4)
            conns.append(c)
        for c in conns:
            c.close()

    t = threading.Thread(target=serve, daemon=True)
    t.start()
    yield f"127.0.0.1:{s.getsockname()[1]}"
    stop.set()
    t.join(5)
    s.close()


@pytest.fixture
def http_server():
    """An HTTP server (the dashboard port given by mistake)."""

    class Quiet(http.server.BaseHTTPRequestHandler):
        def log_message(self, *args):
            pass

    h = http.server.HTTPServer(("127.0.0.1", 0), Quiet)
    t = threading.Thread(target=h.serve_forever, daemon=True)
    t.start()
    yield f"tcp://127.0.0.1:{h.server_address[1]}"
    h.shutdown()
    h.server_close()


def _connect(address):
    with pg.distributed.scheduler_client(address):
        pass  # pragma: no cover - must not connect


@pytest.mark.parametrize("server", ["silent_listener", "http_server", "banner_server"])
def test_not_a_scheduler_is_a_named_error(request, short_deadline, server):
    address = request.getfixturevalue(server)
    with pytest.raises(PhotogeomError) as info:
        _connect(address)
    msg = str(info.value)
    port = address.rsplit(":", 1)[1]
    assert f"Dask scheduler at tcp://127.0.0.1:{port}" in msg
    assert "is a Dask scheduler running there" in msg and "8786" in msg
    assert "MemoryError" not in msg and "Unable to allocate" not in msg


def test_silent_listener_says_no_answer(short_deadline, silent_listener):
    with pytest.raises(PhotogeomError, match=r"no answer from a Dask scheduler within 1\.5 s"):
        _connect(silent_listener)


def test_map_items_on_silent_listener_raises(short_deadline, silent_listener):
    with pytest.raises(PhotogeomError, match="no answer"):
        pg.distributed.map_items(abs, [1, 2], scheduler=silent_listener)


@pytest.mark.parametrize(
    ("address", "words"),
    [
        ("foo:bar", "port 'bar' is not a number"),
        ("tcp://host", "no port"),
        ("tcp://:8786", "no host"),
        ("tcp://127.0.0.1:99999", "not a number from 1 to 65535"),
        ("tcp://127.0.0.1:8786/path", "a path"),
        ("ftp://127.0.0.1:21", "unknown address scheme 'ftp://'"),
        ("http://127.0.0.1:8787", "web address (the Dask dashboard"),
    ],
)
def test_malformed_addresses_refused_before_connecting(address, words):
    with pytest.raises(InputError) as info:
        _connect(address)
    msg = str(info.value)
    assert repr(address) in msg and words in msg
    assert "tcp://host:port" in msg


def test_address_forms_accepted():
    check = pg.distributed._check_address
    assert check("x", "127.0.0.1:8786") == "tcp://127.0.0.1:8786"
    assert check("x", "tls://scheduler.example:8786") == "tls://scheduler.example:8786"
    assert check("x", "tcp://[::1]:8786") == "tcp://[::1]:8786"


def test_real_scheduler_still_connects():
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(
        n_workers=1, threads_per_worker=1, processes=False, dashboard_address=None
    ) as cluster:
        res = pg.distributed.map_items(np.abs, [-1.0, 2.0], scheduler=cluster.scheduler_address)
    assert res.ok and res.results == [1.0, 2.0]


def test_cli_register_with_dashboard_url(cli, tmp_path):
    pytest.importorskip("laspy")
    a, b = tmp_path / "a.las", tmp_path / "b.las"
    x = np.random.default_rng(0).uniform(0, 100, (50, 3))
    pg.io.write_cloud(a, x)
    pg.io.write_cloud(b, x + 1.0)
    code, _out, err = cli("cloud", "register", a, b, "--scheduler", "http://127.0.0.1:8787")
    assert code == 2, err
    assert err.startswith("error: --scheduler 'http://127.0.0.1:8787' is a web address")
    assert "Traceback" not in err


def test_cli_register_with_silent_listener(cli, tmp_path, short_deadline, silent_listener):
    pytest.importorskip("laspy")
    a, b = tmp_path / "a.las", tmp_path / "b.las"
    x = np.random.default_rng(0).uniform(0, 100, (50, 3))
    pg.io.write_cloud(a, x)
    pg.io.write_cloud(b, x + 1.0)
    code, _out, err = cli("cloud", "register", a, b, "--scheduler", silent_listener)
    assert code == 2, err
    assert err.startswith(f"error: Dask scheduler at {silent_listener}: no answer")


def test_folder_correction_on_an_unreachable_scheduler_leaves_no_folder(
    tmp_path, short_deadline, silent_listener
):
    """The output folder (and the parents made for it) is removed again when the job
    cannot start: nothing half-made is left (an empty folder was, before)."""
    import sys
    from pathlib import Path

    import cv2

    from photogeom.calibration import GridLayout, correct_folder

    sys.path.insert(0, str(Path(__file__).parent))
    from residual_grids import grid_with_nodes

    layout = GridLayout(40, 30, 20)
    grid = grid_with_nodes(layout, np.zeros((*layout.shape, 2)))
    src = tmp_path / "in"
    src.mkdir()
    cv2.imwrite(str(src / "a.png"), np.zeros((30, 40), np.uint8))
    out = tmp_path / "new" / "out"
    with pytest.raises(PhotogeomError, match="Dask scheduler"):
        correct_folder(src, out, {"a": grid}, dask=silent_listener)
    assert not (tmp_path / "new").exists()
    # a folder that existed before stays
    (tmp_path / "kept").mkdir()
    with pytest.raises(PhotogeomError, match="Dask scheduler"):
        correct_folder(src, tmp_path / "kept", {"a": grid}, dask=silent_listener)
    assert (tmp_path / "kept").is_dir()
