"""Calls every operation of a running geodex through the Python client that
openapi-python-client generated from its `/openapi.json` (`.ci/clients.sh`).

Each operation is called once through the generated function with a request
built by the generated models (`Model.from_dict`, which picks the tagged
union's variant by its discriminator), and must answer its success status with
a body the generated models parse. Downloads must come back as bytes (NPY,
PNG, PLY). The live answers are also checked against the response schemas of
the served document (jsonschema, draft 2020-12), and so are the document's
own examples.

    python every_operation.py --url http://127.0.0.1:PORT --client DIR
    python every_operation.py ... --record api/examples.json

`--record` writes the requests sent and the answers received (dataset ids
replaced by fixed ones, long lists shortened) as the examples that
`src/http/openapi/clients.rs` puts in the document.
"""

from __future__ import annotations

import argparse
import importlib
import io
import json
import math
import struct
import sys
import time

import httpx
import jsonschema


# --------------------------------------------------------------- test inputs


def npy(rows: list[list[float]], dtype: str = "<f8") -> bytes:
    """A 2D array as NPY version 1.0 bytes."""
    shape = (len(rows), len(rows[0]))
    header = "{'descr': '%s', 'fortran_order': False, 'shape': (%d, %d), }" % (dtype, *shape)
    pad = 64 - (10 + len(header) + 1) % 64
    header = header + " " * pad + "\n"
    code = {"<f8": "d", "|u1": "B"}[dtype]
    body = struct.pack("<%d%s" % (shape[0] * shape[1], code), *[v for row in rows for v in row])
    return b"\x93NUMPY\x01\x00" + struct.pack("<H", len(header)) + header.encode() + body


def image(n: int) -> list[list[float]]:
    """A bright ring road on a dark background, with noise-free texture."""
    c = (n - 1) / 2
    out = []
    for i in range(n):
        row = []
        for j in range(n):
            r = math.hypot(i - c, j - c)
            row.append(0.2 + 0.8 * math.exp(-((r - n / 3) ** 2) / 8.0) + 0.05 * math.sin(j / 3))
        out.append(row)
    return out


def mask(n: int) -> list[list[float]]:
    """A filled square with a notch."""
    return [[1.0 if 8 <= i < n - 8 and 8 <= j < n - 8 and not (i < n // 2 and n // 2 - 2 <= j <= n // 2 + 2) else 0.0
             for j in range(n)] for i in range(n)]


def shading(n: int) -> list[list[float]]:
    """A Gaussian bump lit from the front: I = 1 / sqrt(1 + |grad z|^2)."""
    c = (n - 1) / 2
    out = []
    for i in range(n):
        row = []
        for j in range(n):
            x, y = (i - c) / n, (j - c) / n
            z = 0.3 * math.exp(-(x * x + y * y) / 0.02)
            zx, zy = -x / 0.01 * z, -y / 0.01 * z
            row.append(1.0 / math.sqrt(1.0 + (zx / n) ** 2 + (zy / n) ** 2))
        out.append(row)
    return out


def torus_obj(n: int = 24, m: int = 12, big: float = 1.0, small: float = 0.4) -> bytes:
    """A torus of n x m vertices as OBJ text."""
    lines = []
    for i in range(n):
        u = 2 * math.pi * i / n
        for j in range(m):
            v = 2 * math.pi * j / m
            r = big + small * math.cos(v)
            lines.append("v %.6f %.6f %.6f" % (r * math.cos(u), r * math.sin(u), small * math.sin(v)))
    for i in range(n):
        for j in range(m):
            a, b = i * m + j, ((i + 1) % n) * m + j
            c, d = ((i + 1) % n) * m + (j + 1) % m, i * m + (j + 1) % m
            lines.append("f %d %d %d" % (a + 1, b + 1, c + 1))
            lines.append("f %d %d %d" % (a + 1, c + 1, d + 1))
    return ("\n".join(lines) + "\n").encode()


def swiss_roll(count: int = 120) -> list[list[float]]:
    """Points on a rolled sheet (deterministic)."""
    pts = []
    for k in range(count):
        t = 1.5 * math.pi * (1 + 2 * ((k * 0.618034) % 1.0))
        h = 10.0 * ((k * 0.414214) % 1.0)
        pts.append([t * math.cos(t), h, t * math.sin(t)])
    return pts


# ------------------------------------------------------------------ the run


class Run:
    """The generated client, the served document and what was called."""

    def __init__(self, url: str, package: str) -> None:
        self.pkg = importlib.import_module(package)
        self.api = lambda tag, name: importlib.import_module(f"{package}.api.{tag}.{name}")
        self.models = importlib.import_module(f"{package}.models")
        self.types = importlib.import_module(f"{package}.types")
        self.client = self.pkg.Client(base_url=url, timeout=httpx.Timeout(120.0), raise_on_unexpected_status=True)
        self.doc = httpx.get(url + "/openapi.json").json()
        self.by_id = {}
        for path, item in self.doc["paths"].items():
            for method, op in item.items():
                self.by_id[op["operationId"]] = (method, path, op)
        self.called: set[str] = set()
        self.recorded: dict[str, dict] = {}
        self.ids: dict[str, str] = {}

    def fake_id(self, real: str) -> str:
        """A fixed id for a real dataset or job id (for the recorded examples)."""
        if real not in self.ids:
            prefix = real.split("_")[0]
            self.ids[real] = "%s_0192f1b27c1e7d3a9d553c0f2b8a1e%02x" % (prefix, 0x40 + len(self.ids))
        return self.ids[real]

    def validate(self, op_id: str, status: int, body) -> None:
        """The answer conforms to the response schema of the document."""
        method, path, op = self.by_id[op_id]
        resp = op["responses"][str(status)]
        schema = resp.get("content", {}).get("application/json", {}).get("schema")
        if schema is None:
            return
        root = {"components": self.doc["components"], **schema}
        try:
            jsonschema.Draft202012Validator(root).validate(body)
        except jsonschema.ValidationError as e:
            raise AssertionError(f"{op_id}: answer {status} does not match its schema: {e.message} at {list(e.path)}")

    def call(self, tag: str, op_id: str, status: int, *args, record=None, **kwargs):
        """Calls the generated `sync_detailed`; checks status and parsing."""
        module = self.api(tag, op_id)
        t0 = time.perf_counter()
        res = module.sync_detailed(*args, client=self.client, **kwargs)
        ms = (time.perf_counter() - t0) * 1e3
        if res.status_code != status:
            raise AssertionError(f"{op_id}: expected {status}, got {res.status_code}: {res.content[:400]!r}")
        if res.parsed is None and status != 204:
            raise AssertionError(f"{op_id}: the generated client did not parse the {status} answer")
        content_type = res.headers.get("content-type", "")
        if "json" in content_type:
            body = json.loads(res.content)
            self.validate(op_id, status, body)
            if record is not None or self.recorded.get(op_id, {}).get("request") is None:
                self.recorded[op_id] = {"request": record, "status": str(status), "response": body}
        self.called.add(op_id)
        print(f"  {op_id:<22} {res.status_code} {type(res.parsed).__name__:<24} {ms:7.1f} ms")
        return res

    def body(self, model: str, data: dict):
        """A generated request model, built from its JSON form."""
        return getattr(self.models, model).from_dict(data)

    def post(self, tag: str, op_id: str, model: str, data: dict, status: int = 200, **kw):
        body = self.body(model, data)
        sent = body.to_dict()
        return self.call(tag, op_id, status, body=body, record=sent, **kw)

    def upload(self, data: bytes, name: str) -> str:
        res = self.call("datasets", "upload", 201, body=self.types.File(payload=io.BytesIO(data), file_name=name))
        return res.parsed.id


def every_operation(run: Run) -> None:
    n = 64
    img = run.upload(npy(image(n)), "ring.npy")
    msk = run.upload(npy(mask(n)), "mask.npy")
    shade = run.upload(npy(shading(48)), "bump.npy")
    mesh = run.upload(torus_obj(), "torus.obj")
    pts = run.upload(npy(swiss_roll()), "roll.npy")

    # datasets
    run.call("datasets", "datasets_list", 200, limit=2)
    run.call("datasets", "get_meta", 200, img)
    data = run.call("datasets", "get_data", 200, img)
    assert data.content[:6] == b"\x93NUMPY", "a download is read as NPY bytes"
    assert isinstance(data.parsed, run.types.File), type(data.parsed)
    run.call("datasets", "get_data", 200, img, format_=run.models.GetDataFormat("png"))

    # grid
    road = {"dataset": img, "design": {"kind": "intensity", "at": [10.5, 31.5]}}
    distance = run.post("grid", "grid_distance", "GridDistanceRequest",
                        {"cost": road, "sources": [{"point": [10.5, 31.5]}], "order": 2})
    assert distance.parsed.distance.id
    run.post("grid", "edt", "GridEdtRequest", {"mask": msk, "mode": "signed"})
    run.post("grid", "segment", "GridSegmentRequest",
             {"cost": {"dataset": img}, "seeds": [{"label": 1, "point": [5, 5]}, {"label": 2, "point": [58, 58]}]})
    run.post("grid", "skeleton", "GridSkeletonRequest", {"mask": msk})
    run.post("grid", "shape_embed", "GridShapeEmbedRequest", {"mask": msk, "landmarks": 12})
    run.post("grid", "offset", "GridOffsetRequest", {"mask": msk, "operation": "dilate", "radius": 3.0})
    run.post("grid", "plan", "GridPlanRequest",
             {"obstacles": msk, "start": [2, 2], "goal": [61, 61], "radius": 1.5})
    run.post("grid", "grid_sample", "GridSampleRequest",
             {"cost": {"constant": 1.0, "shape": [n, n]}, "count": 12})
    run.post("grid", "mesh", "GridMeshRequest", {"dataset": img, "count": 120, "metric": "hessian"})
    run.post("grid", "domain_mesh", "DomainMeshRequest", {
        "count": 150,
        "polygons": {"type": "Polygon", "coordinates": [[[0, 0], [40, 0], [40, 40], [0, 40]],
                                                        [[15, 15], [25, 15], [25, 25], [15, 25]]]}})
    run.post("grid", "shape_from_shading", "GridShadingRequest",
             {"image": shade, "anchors": {"kind": "border", "height": 0.0}})
    run.post("grid", "cost_gradient", "GridCostGradientRequest", {
        "cost": {"constant": 1.0, "shape": [n, n]}, "sources": [{"point": [32.0, 4.0]}],
        "targets": [{"point": [32.0, 60.0]}]})
    run.post("grid", "tomography", "GridTomographyRequest", {
        "shape": [32, 32], "alpha": 0.5, "iterations": 3,
        "sources": [{"point": [0.0, 0.0]}, {"point": [0.0, 31.0]}],
        "receivers": [{"point": [31.0, 0.0]}, {"point": [31.0, 31.0]}],
        "times": [[31.0, 43.8], [43.8, 31.0]]})
    run.post("grid", "fit_metric", "GridFitMetricRequest", {
        "image": img, "design": {"kind": "intensity", "power": 2.0}, "iterations": 3,
        "examples": [[[10.5, 31.5], [14.0, 18.0], [24.0, 10.5], [31.5, 10.0]]]})
    run.post("grid", "group", "GridGroupRequest", {
        "cost": {"constant": 1.0, "shape": [n, n]},
        "key_points": [[10.0, 10.0], [10.0, 20.0], [10.0, 30.0], [50.0, 50.0]]})
    run.post("grid", "metric", "GridMetricRequest",
             {"cost": {"dataset": img, "design": {"kind": "vesselness", "polarity": "bright", "scales": [1.0, 2.0]}}})
    run.post("grid", "grid_paths", "GridPathsRequest",
             {"cost": road, "sources": [{"point": [10.5, 31.5]}], "ends": [[53.5, 31.5], [31.5, 10.0]]})
    run.post("grid", "tensor_distance", "GridTensorDistanceRequest", {
        "metric": {"kind": "eigen", "shape": [n, n], "eigenvalues": [1.0, 9.0], "direction": [1.0, 1.0]},
        "sources": [{"point": [32.0, 32.0]}], "ends": [[5.0, 50.0]]})
    run.post("grid", "tensor_metric", "GridTensorMetricRequest", {
        "metric": {"kind": "energy_anisotropy", "shape": [n, n], "energy": 1.0, "anisotropy": 0.8, "angle": 0.5}})

    # the multipart form of grid.distance: the cost travels in the request
    form = run.models.DistanceForm(
        params=json.dumps({"sources": [{"point": [3.0, 3.0]}]}),
        file=run.types.File(payload=io.BytesIO(npy(image(32))), file_name="cost.npy"),
    )
    res = run.call("grid", "grid_distance", 200, body=form)
    assert res.parsed.distance.id

    # meshes
    run.post("mesh", "mesh_distance", "MeshDistanceRequest",
             {"mesh": mesh, "method": "heat", "sources": [{"vertex": 0}, {"face": 12, "bary": [0.2, 0.3, 0.5]}]})
    run.post("mesh", "voronoi", "MeshVoronoiRequest",
             {"mesh": mesh, "sources": [{"vertex": 0}, {"vertex": 150}]})
    run.post("mesh", "mesh_paths", "MeshPathsRequest",
             {"mesh": mesh, "sources": [{"vertex": 0}], "ends": [{"vertex": 150}, {"face": 40, "bary": [0.3, 0.3, 0.4]}]})
    run.post("mesh", "mesh_sample", "MeshSampleRequest", {"mesh": mesh, "count": 10})
    run.post("mesh", "curvature", "MeshCurvatureRequest", {"mesh": mesh, "smoothing": 2})
    # The surface metric section through the generated models: a design, the
    # curvature tensors and a constant tensor.
    run.post("mesh", "mesh_sample", "MeshSampleRequest",
             {"mesh": mesh, "count": 10, "metric": {"kind": "curvature", "feature": "both"}})
    run.post("mesh", "mesh_distance", "MeshDistanceRequest",
             {"mesh": mesh, "sources": [{"vertex": 0}], "metric": {"kind": "curvature_tensors", "max_ratio": 4}})
    run.post("mesh", "mesh_paths", "MeshPathsRequest",
             {"mesh": mesh, "sources": [{"vertex": 0}], "ends": [{"vertex": 150}],
              "metric": {"kind": "tensors", "constant": [[2, 0, 0], [0, 1, 0], [0, 0, 1]]}})
    run.post("mesh", "remesh", "MeshRemeshRequest", {"mesh": mesh, "count": 120})
    run.post("mesh", "distance_matrix", "MeshDistanceMatrixRequest",
             {"mesh": mesh, "landmarks": 4, "method": "heat"})
    run.post("mesh", "distance_matrix", "MeshDistanceMatrixRequest",
             {"mesh": mesh, "sources": [0, 5], "metric": {"kind": "curvature_tensors", "max_ratio": 4}})
    run.post("mesh", "embed", "MeshEmbedRequest", {"mesh": mesh, "landmarks": 40})
    run.post("mesh", "descriptor", "MeshDescriptorRequest", {"mesh": mesh, "landmarks": 16, "bins": 8})

    # collections
    created = run.post("collections", "create_collection", "CreateCollection",
                       {"name": "poses", "descriptor": {"landmarks": 16, "bins": 8}}, status=201)
    col = created.parsed.id
    run.post("collections", "add_shape", "AddShape", {"mesh": mesh, "name": "torus", "label": "torus"},
             status=201, id=col)
    found = run.post("collections", "query_collection", "QueryCollection", {"mesh": mesh, "k": 5}, id=col)
    assert found.parsed.matches[0].shape.label == "torus", found.parsed
    run.call("collections", "list_collections", 200)
    run.call("collections", "get_collection", 200, col)
    run.call("collections", "delete_collection", 204, col)
    run.post("mesh", "correspond", "MeshCorrespondRequest", {"a": mesh, "b": mesh, "landmarks": 20})
    run.post("points", "isomap", "PointsIsomapRequest", {"points": pts, "k": 8, "dimensions": 2})

    # operations
    run.call("operations", "healthz", 200)
    run.call("operations", "readyz", 200)
    run.call("operations", "metrics", 200)

    # jobs
    job = run.post("jobs", "submit", "SubmitJob", {
        "operation": "grid.distance",
        "params": {"cost": {"constant": 1.0, "shape": [n, n]}, "sources": [{"point": [32.0, 32.0]}]}},
        status=202)
    job_id = job.parsed.id
    for _ in range(600):
        got = run.call("jobs", "get", 200, job_id)
        if got.parsed.state.value in ("succeeded", "failed", "cancelled"):
            break
        time.sleep(0.1)
    assert got.parsed.state.value == "succeeded", got.parsed.state
    run.call("jobs", "jobs_list", 200)
    result = run.call("jobs", "result", 200, job_id, "distance")
    assert result.content[:6] == b"\x93NUMPY", "a job result is read as NPY bytes"
    slow = run.body("SubmitJob", {
        "operation": "grid.distance",
        "params": {"cost": {"constant": 1.0, "shape": [2048, 2048]}, "sources": [{"point": [0.0, 0.0]}]}})
    slow_id = run.call("jobs", "submit", 202, body=slow).parsed.id
    run.call("jobs", "cancel", 202, slow_id)

    # a dataset is deleted
    run.call("datasets", "delete", 204, pts)


def check_examples(run: Run) -> int:
    """Every example of the document conforms to its schema."""
    checked = 0
    for op_id, (method, path, op) in run.by_id.items():
        body = op.get("requestBody", {}).get("content", {}).get("application/json")
        if body and "example" in body:
            root = {"components": run.doc["components"], **body["schema"]}
            jsonschema.Draft202012Validator(root).validate(body["example"])
            checked += 1
        for status, resp in op["responses"].items():
            c = resp.get("content", {}).get("application/json")
            if c and "example" in c and "schema" in c:
                root = {"components": run.doc["components"], **c["schema"]}
                try:
                    jsonschema.Draft202012Validator(root).validate(c["example"])
                except jsonschema.ValidationError as e:
                    raise AssertionError(f"{op_id} {status}: example: {e.message} at {list(e.path)}")
                checked += 1
    return checked


def shorten(value):
    """Long lists cut to 6 items, numbers to 6 significant digits."""
    if isinstance(value, list):
        return [shorten(v) for v in value[:6]]
    if isinstance(value, dict):
        return {k: shorten(v) for k, v in value.items()}
    if isinstance(value, float):
        return float("%.6g" % value)
    return value


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--url", required=True)
    parser.add_argument("--client", required=True, help="folder that holds the generated package")
    parser.add_argument("--package", default="geodex_client")
    parser.add_argument("--record", help="write the examples here")
    args = parser.parse_args()
    sys.path.insert(0, args.client)
    run = Run(args.url.rstrip("/"), args.package)
    print(f"calling {len(run.by_id)} operations through the generated client")
    every_operation(run)
    missing = sorted(set(run.by_id) - run.called)
    if missing:
        print(f"operations not called: {missing}")
        return 1
    checked = check_examples(run)
    print(f"{len(run.called)} of {len(run.by_id)} operations called; {checked} examples conform to their schemas")
    if args.record:
        examples = {}
        for op_id, rec in sorted(run.recorded.items()):
            examples[op_id] = shorten(rec)
        # ids seen anywhere in the recorded calls become fixed ones, in order
        text = json.dumps(examples, indent=2, sort_keys=True)
        for real in dict.fromkeys(_ids(text)):
            text = text.replace(real, run.fake_id(real))
        with open(args.record, "w") as f:
            f.write(text + "\n")
        print(f"recorded {len(examples)} examples in {args.record}")
    print(f"client: {len(run.called)} passed, 0 failed")
    return 0


def _ids(text: str):
    import re
    return re.findall(r"(?:ds|job)_[0-9a-f]{32}", text)


if __name__ == "__main__":
    sys.exit(main())
