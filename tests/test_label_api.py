"""jaxmatch label: the web app's API through Starlette's TestClient, the labels store, the command.

Small sizes (k = 2, top 3) keep the ranking quick.
"""

import json
import threading
from pathlib import Path

import pytest

from jaxmatch.errors import InputError

ROOT = Path(__file__).resolve().parents[1]
EX = ROOT / "examples"
# starlette's TestClient asks for the 'httpx2' package (not on PyPI mirrors here); httpx works
pytestmark = pytest.mark.filterwarnings("ignore:Using .httpx. with .starlette.testclient.")
SQUARE = {"boundary": [[0, 0], [1, 0], [1, 1], [0, 1]]}


@pytest.fixture
def make(tmp_path):
    """``make(*shapes, **options) -> (TestClient, session)`` for a labels file in tmp_path."""
    from starlette.testclient import TestClient

    from jaxmatch.label.app import LabelSession, create_app

    def build(*shapes, labels=None, **opts):
        opts.setdefault("internal", 2)
        opts.setdefault("top", 3)
        session = LabelSession([str(s) for s in shapes], labels or tmp_path / "labels.jsonl", **opts)
        return TestClient(create_app(session), raise_server_exceptions=False), session

    return build


def _lines(path):
    return [json.loads(x) for x in Path(path).read_text().splitlines() if x.strip() and not x.startswith("#")]


def test_page_and_static_files(make):
    client, _ = make(EX / "lshape.json")
    page = client.get("/")
    assert page.status_code == 200 and "jaxmatch label" in page.text and "/static/app.js" in page.text
    assert client.get("/static/app.js").status_code == 200
    assert client.get("/static/style.css").status_code == 200
    assert client.get("/static/../app.py").status_code == 404


def test_candidates_and_choose(make, tmp_path, index):
    from jaxmatch.tuning.labels import load_labels

    client, _ = make(EX / "lshape.json", EX / "square.json")
    st = client.get("/api/state").json()
    assert st["total"] == 2 and st["labelled"] == 0 and [s["name"] for s in st["shapes"]] == ["lshape.json", "square.json"]
    data = client.get("/api/shapes/0").json()
    assert data["name"] == "lshape.json" and len(data["outline"]) == 6
    assert {p["code"] for p in data["points"]} == {"s", "x", "v"}
    cands = data["candidates"]
    assert len(cands) == 3 and all(c["mesh_id"].startswith("k2-") for c in cands)
    for c in cands:
        assert len(c["xy"]) == len(c["valence"]) and max(max(q) for q in c["quads"]) < len(c["xy"])
        assert -1 <= c["min_scaled_jacobian"] <= 1 and c["utility"] > 0
        assert all(0 <= b < len(c["xy"]) for b in c["boundary"])
    pick = cands[1]
    r = client.post("/api/shapes/0/choose", json={"mesh_id": pick["mesh_id"]})
    assert r.status_code == 200, r.text
    assert r.json()["labelled"] == 1
    lines = _lines(tmp_path / "labels.jsonl")
    assert len(lines) == 1 and set(lines[0]) == {"shape", "preferred", "rotation", "reflected"}
    assert (lines[0]["preferred"], lines[0]["rotation"], lines[0]["reflected"]) == (pick["mesh_id"], pick["rotation"], pick["reflected"])
    assert (tmp_path / lines[0]["shape"]).resolve() == (EX / "lshape.json").resolve()
    # the file feeds the tuner's reader unchanged
    loaded = load_labels(tmp_path / "labels.jsonl", index)
    assert [e.preferred for e in loaded.examples] == [pick["mesh_id"]] and loaded.examples[0].k == 2
    assert client.get("/api/state").json()["shapes"][0]["mark"] == pick["mesh_id"]
    # "none of these": a comment line, the tuner skips it
    assert client.get("/api/shapes/1").status_code == 200
    r = client.post("/api/shapes/1/choose", json={"none": True})
    assert r.status_code == 200 and r.json()["labelled"] == 2
    assert len(load_labels(tmp_path / "labels.jsonl", index).examples) == 1
    assert client.get("/api/state").json()["shapes"][1]["mark"] == "none"


def test_resume_marks_labelled_shapes(make, tmp_path):
    client, _ = make(EX / "lshape.json", EX / "square.json")
    mid = client.get("/api/shapes/1").json()["candidates"][0]["mesh_id"]
    assert client.post("/api/shapes/1/choose", json={"mesh_id": mid}).status_code == 200
    drawn = client.post("/api/shapes", json=SQUARE | {"boundary": [[0, 0], [3, 0], [3, 1], [0, 1]]}).json()["id"]
    mid2 = client.get(f"/api/shapes/{drawn}").json()["candidates"][0]["mesh_id"]
    assert client.post(f"/api/shapes/{drawn}/choose", json={"mesh_id": mid2}).status_code == 200
    # the same labels file opened again: the square is marked, the drawn shape is listed again, marked
    client2, _ = make(EX / "lshape.json", EX / "square.json")
    st = client2.get("/api/state").json()
    assert st["total"] == 3 and st["labelled"] == 2
    assert [s["mark"] for s in st["shapes"]] == [None, mid, mid2]
    assert client2.get("/api/shapes/1").json()["mark"] == mid
    # no shapes on the command line: the labelled ones come from the file
    client3, _ = make()
    assert client3.get("/api/state").json()["total"] == 2


def test_bad_requests_are_4xx_with_a_message(make, tmp_path):
    client, _ = make(EX / "lshape.json")
    # a mesh id must be one of the candidates shown for that shape
    assert client.post("/api/shapes/0/choose", json={"mesh_id": "k2-045f3977f5d8"}).status_code == 409  # nothing shown yet
    ids = [c["mesh_id"] for c in client.get("/api/shapes/0").json()["candidates"]]
    other = "k3-8926e6d5d345"
    assert other not in ids
    for body in ({"mesh_id": other}, {"mesh_id": 3}, {"mesh_id": "../../etc/passwd"}, {}, [1, 2]):
        r = client.post("/api/shapes/0/choose", json=body)
        assert r.status_code == 400 and "error" in r.json() and "Traceback" not in r.text, body
    r = client.post("/api/shapes/0/choose", content=b"{not json", headers={"content-type": "application/json"})
    assert r.status_code == 400 and "not valid JSON" in r.json()["error"]
    assert client.get("/api/shapes/7").status_code == 404
    assert client.get("/api/shapes/7").json()["error"].startswith("unknown shape")
    assert client.get("/api/nothing").status_code == 404
    assert not (tmp_path / "labels.jsonl").exists()  # nothing written by bad requests
    # bad shapes: the CLI's checks and messages
    bowtie = {"boundary": [[0, 0], [1, 1], [1, 0], [0, 1]]}
    for body, words in ((bowtie, "crosses"), ({"boundary": [[0, 0], [1, 0]]}, "at least 3"),
                        ({"boundary": "x"}, "boundary"), ({"boundary": [[0, 0], [1, 0], [1, 1]], "corners": [7]}, "corner")):
        r = client.post("/api/shapes", json=body)
        assert r.status_code == 400 and words in r.json()["error"].lower(), (body, r.text)
    r = client.post("/api/upload?name=shape.json", content=b'{"boundary": [[0, 0], [1, 0]]}')
    assert r.status_code == 400 and r.json()["error"].startswith("shape.json:")
    r = client.post("/api/upload?name=/etc/passwd", content=b"root:x:0:0:root:/root:/bin/bash\n")
    assert r.status_code == 400 and "passwd" in r.json()["error"] and "root:x" not in r.json()["error"][:8]
    assert client.post("/api/upload?name=a.csv", content=b"").status_code == 400
    assert client.post("/api/upload", content=b"x" * (9 * 2**20)).status_code == 413
    assert client.get("/api/state").json()["total"] == 1


def test_dropped_files_of_every_format(make, tmp_path):
    client, _ = make(EX / "square.json")
    for name in ("lshape.csv", "plate.geojson", "slot.dxf", "curved.json"):
        r = client.post(f"/api/upload?name={name}", content=(EX / name).read_bytes())
        assert r.status_code == 200, (name, r.text)
        data = client.get(f"/api/shapes/{r.json()['id']}").json()
        assert data["name"] == name and data["candidates"]
        assert isinstance(data["spec"], dict) and "boundary" in data["spec"]
    # the same shape dropped twice is one shape
    again = client.post("/api/upload?name=lshape.csv", content=(EX / "lshape.csv").read_bytes()).json()["id"]
    assert again == 1
    # a drawn shape is labelled inline and re-parses to the same shape
    sid = client.post("/api/shapes", json=SQUARE | {"corners": [0, 1, 2, 3]}).json()["id"]
    data = client.get(f"/api/shapes/{sid}").json()
    mid = data["candidates"][0]["mesh_id"]
    assert client.post(f"/api/shapes/{sid}/choose", json={"mesh_id": mid}).status_code == 200
    rec = _lines(tmp_path / "labels.jsonl")[-1]
    assert rec["shape"]["corners"] == [0, 1, 2, 3] and len(rec["shape"]["boundary"]) == 4


def test_concurrent_choices_from_threads(make, tmp_path, index):
    from jaxmatch.tuning.labels import load_labels

    client, session = make(EX / "lshape.json", EX / "square.json", EX / "tshape.json")
    ids = [[c["mesh_id"] for c in client.get(f"/api/shapes/{i}").json()["candidates"]] for i in range(3)]
    errors = []

    def worker(t):
        try:
            for j in range(10):
                i = (t + j) % 3
                r = client.post(f"/api/shapes/{i}/choose", json={"mesh_id": ids[i][j % len(ids[i])]})
                assert r.status_code == 200, r.text
        except Exception as e:  # noqa: BLE001 - reported below
            errors.append(e)

    # one event loop serves every thread's requests (as uvicorn does), not one started per request
    with client:
        threads = [threading.Thread(target=worker, args=(t,)) for t in range(8)]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
    assert not errors
    text = (tmp_path / "labels.jsonl").read_text()
    assert text.endswith("\n") and len(text.splitlines()) == 80
    assert len(load_labels(tmp_path / "labels.jsonl", index).examples) == 80  # every line whole and valid


def test_store_append_is_whole_lines(tmp_path):
    from jaxmatch.label.store import LabelStore

    path = tmp_path / "l.jsonl"
    path.write_text('{"shape": "a.json", "prefer')  # a half line left by something else
    store = LabelStore(path)
    store.add_label("b.json", "k2-045f3977f5d8", 1, False)
    lines = path.read_text().splitlines()
    assert lines[-1] == '{"shape": "b.json", "preferred": "k2-045f3977f5d8", "rotation": 1, "reflected": false}'
    assert list(store.marks()) == ["b.json"]
    with pytest.raises(ValueError):
        store.append("two\nlines")
    (tmp_path / "folder.jsonl").mkdir()
    with pytest.raises(InputError, match="cannot write labels"):
        LabelStore(tmp_path / "folder.jsonl").append("{}")


def test_store_separate_writers_never_interleave(tmp_path):
    """Separate stores (as two servers on one file): long lines stay whole (flock + O_APPEND)."""
    from jaxmatch.label.store import LabelStore

    path = tmp_path / "l.jsonl"

    def writer(t):
        store = LabelStore(path)
        for j in range(40):
            store.append(json.dumps({"shape": "s.json", "preferred": f"k2-{t:02d}{j:02d}", "note": str(t) * 20000}))

    threads = [threading.Thread(target=writer, args=(t,)) for t in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    lines = path.read_text().splitlines()
    assert len(lines) == 160
    for line in lines:
        rec = json.loads(line)
        assert rec["note"] == rec["preferred"][4] * 20000  # whole, and its own writer's


def test_tune_action_and_command(make, tmp_path, cli):
    client, session = make(EX / "lshape.json", EX / "square.json", EX / "tshape.json", EX / "plus.json", epochs=1)
    r = client.post("/api/tune")
    assert r.status_code == 400 and "no labels yet" in r.json()["error"]
    for i in range(4):
        c = client.get(f"/api/shapes/{i}").json()["candidates"]
        assert client.post(f"/api/shapes/{i}/choose", json={"mesh_id": c[i % len(c)]["mesh_id"]}).status_code == 200
    assert client.post("/api/shapes/3/choose", json={"none": True}).status_code == 200  # the last line decides
    r = client.post("/api/tune")
    assert r.status_code == 200, r.text
    res = r.json()
    assert res["examples"] == 3 and res["out"] == str(tmp_path / "labels.tuned.toml")
    assert res["train"]["examples"] + res["heldout"]["examples"] == 3
    for key in ("train", "heldout"):
        for m in ("top1", "top5"):
            assert set(res[key][m]) == {"before", "after"}
    assert "[levels" in res["toml"] or "levels" in res["toml"]
    from jaxmatch.scoring.lattice import load_lattice

    assert load_lattice(tmp_path / "labels.tuned.toml").name == "fine-tuned"
    # the command
    code, out, err = cli("label", "--labels", tmp_path / "labels.jsonl", "--tune", "--out", tmp_path / "t.toml", "--epochs", "1")
    assert code == 0, err
    assert "top-1 before" in out and "heldout" in out and (tmp_path / "t.toml").is_file()


def test_command_bad_input_is_one_line_exit_2(cli, tmp_path):
    labels = tmp_path / "l.jsonl"
    cases = [
        (["label", EX / "nope.json", "--labels", labels], "nope.json"),
        (["label", EX / "lshape.json", "--labels", tmp_path / "no" / "l.jsonl"], "folder does not exist"),
        (["label", EX / "lshape.json", "--labels", labels, "--internal", "9"], "--internal"),
        (["label", EX / "lshape.json", "--labels", labels, "--top", "12"], "--top"),
        (["label", EX / "lshape.json", "--labels", labels, "--size", "-1"], "--size"),
        (["label", "--labels", labels, "--tune"], "--out"),
        (["label", "--labels", labels, "--tune", "--out", tmp_path / "t.toml"], "no labels yet"),
    ]
    import socket

    busy = socket.socket()
    busy.bind(("127.0.0.1", 0))
    busy.listen(1)
    cases += [(["label", EX / "square.json", "--labels", labels, "--port", busy.getsockname()[1]], "cannot listen"),
              (["label", EX / "square.json", "--labels", labels, "--host", "a b"], "--host")]
    try:
        for args, words in cases:
            code, out, err = cli(*args)
            assert code == 2, (args, out, err)
            assert len(err.strip().splitlines()) == 1 and words in err, (args, err)
    finally:
        busy.close()


def test_size_shows_refined_meshes_labels_the_template(make, tmp_path):
    client, _ = make(EX / "square.json")
    plain = client.get("/api/shapes/0").json()["candidates"]
    client2, _ = make(EX / "square.json", labels=tmp_path / "sized.jsonl", size=0.2)
    sized = client2.get("/api/shapes/0").json()["candidates"]
    assert [c["mesh_id"] for c in sized] == [c["mesh_id"] for c in plain]
    assert all(len(s["quads"]) > len(p["quads"]) for s, p in zip(sized, plain) if not s["note"])
    assert client2.post("/api/shapes/0/choose", json={"mesh_id": sized[0]["mesh_id"]}).status_code == 200
    assert _lines(tmp_path / "sized.jsonl")[0]["preferred"] == sized[0]["mesh_id"]
