"""Loading and normalising meshes in every supported format, and bad mesh files."""

import numpy as np
import pytest
import trimesh

from tests.conftest import sample, sample_files
from viewdb.catalogue.mesh import LoadOptions, load_mesh, mesh_from_glb, missing_textures
from viewdb.errors import MeshError


def test_every_format_is_present_among_the_samples():
    suffixes = {p.suffix.lower() for p in sample_files()}
    assert {".obj", ".ply", ".stl", ".off", ".glb"} <= suffixes


@pytest.mark.parametrize("path", sample_files(), ids=lambda p: p.name)
def test_normalised_bbox_centre_at_origin_and_radius_one(path):
    mesh = load_mesh(path)
    v = mesh.geometry.vertices
    np.testing.assert_allclose((v.min(0) + v.max(0)) / 2, 0, atol=1e-9)
    assert np.linalg.norm(v, axis=1).max() == pytest.approx(1.0, abs=1e-9)
    # the original placement is recoverable: original = centre + scale * normalised
    raw = trimesh.load(str(path), force="mesh", process=False)
    np.testing.assert_allclose(
        np.sort((mesh.centre + mesh.scale * v).ravel()), np.sort(np.asarray(raw.vertices).ravel()), atol=1e-6
    )


@pytest.mark.parametrize("stem", ["car", "mug", "bottle", "cube_dice"])
def test_textures_survive_the_glb_round_trip(stem):
    mesh = load_mesh(sample(stem))
    back = mesh_from_glb(mesh.to_glb(), stem)
    kinds = {g.visual.kind for g in back.scene.geometry.values()}
    assert kinds & {"texture"}, kinds
    materials = [g.visual.material for g in back.scene.geometry.values()]
    assert any(getattr(m, "baseColorTexture", None) is not None for m in materials)
    np.testing.assert_allclose(back.geometry.bounds, mesh.geometry.bounds, atol=1e-6)


@pytest.mark.parametrize("stem", ["torus", "marked_cube"])
def test_vertex_and_face_colours_survive_the_glb_round_trip(stem):
    mesh = load_mesh(sample(stem))
    back = mesh_from_glb(mesh.to_glb(), stem)
    colours = np.vstack([g.visual.vertex_colors for g in back.scene.geometry.values()])
    assert len(np.unique(colours[:, :3], axis=0)) >= 6


def test_scene_node_transforms_are_baked(tmp_path):
    a = trimesh.creation.box((1, 1, 1))
    scene = trimesh.Scene()
    scene.add_geometry(a, node_name="left", transform=trimesh.transformations.translation_matrix([-5, 0, 0]))
    scene.add_geometry(a, node_name="right", transform=trimesh.transformations.translation_matrix([5, 0, 0]))
    path = tmp_path / "two.glb"
    scene.export(path)
    mesh = load_mesh(path)
    assert mesh.scale == pytest.approx(np.linalg.norm([5.5, 0.5, 0.5]))
    xs = mesh.geometry.vertices[:, 0]
    assert xs.min() == pytest.approx(-5.5 / mesh.scale) and xs.max() == pytest.approx(5.5 / mesh.scale)


def write(tmp_path, name, content):
    p = tmp_path / name
    p.write_bytes(content if isinstance(content, bytes) else content.encode())
    return p


@pytest.mark.parametrize(
    "name, content, message",
    [
        ("empty.obj", "", "no triangles|cannot be read"),
        ("points.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\n", "no triangle|cannot be read"),
        ("flat.obj", "v 0 0 0\nv 1 1 1\nv 2 2 2\nf 1 2 3\n", "no surface area"),
        ("dot.obj", "v 1 1 1\nv 1 1 1\nv 1 1 1\nf 1 2 3\n", "no extent"),
        ("garbage.stl", b"\x00\x01garbage" * 10, "cannot be read|no triangles"),
        ("garbage.glb", b"glTF" + b"\xff" * 40, "cannot be read"),
        ("nan.off", "OFF\n3 1 0\nnan 0 0\n1 0 0\n0 1 0\n3 0 1 2\n", "non-finite|cannot be read"),
        ("model.xyz", "1 2 3\n", "unsupported file type"),
    ],
)
def test_bad_meshes_get_a_one_line_error_naming_the_file(tmp_path, name, content, message):
    path = write(tmp_path, name, content)
    with pytest.raises(MeshError, match=message) as info:
        load_mesh(path)
    text = str(info.value)
    assert str(path) in text and "\n" not in text


def test_missing_file(tmp_path):
    with pytest.raises(MeshError, match="no such file"):
        load_mesh(tmp_path / "nope.obj")


def test_jpeg_textures_stay_jpeg_in_the_stored_glb(tmp_path):
    import io

    from PIL import Image

    rng = np.random.default_rng(1)
    noise = Image.fromarray(rng.integers(0, 255, (256, 256, 3), dtype=np.uint8))
    buf = io.BytesIO()
    noise.save(buf, format="JPEG", quality=80)
    jpeg = Image.open(io.BytesIO(buf.getvalue()))
    box = trimesh.creation.box((1, 1, 1))
    uv = rng.random((len(box.vertices), 2))
    box.visual = trimesh.visual.TextureVisuals(uv=uv, image=jpeg)
    path = tmp_path / "textured.glb"
    path.write_bytes(trimesh.Scene(box).export(file_type="glb"))
    stored = load_mesh(path).to_glb()
    assert b"image/jpeg" in stored
    assert len(stored) < 1.2 * path.stat().st_size


OBJ_WITH_TEXTURE = """mtllib box.mtl
v 0 0 0
v 1 0 0
v 1 1 0
v 0 0 1
vt 0 0
vt 1 0
vt 1 1
usemtl skin
f 1/1 2/2 3/3
f 1/1 2/2 4/3
f 2/1 3/2 4/3
f 1/1 3/2 4/3
"""


def _textured_obj(tmp_path, with_library=True, with_image=True):
    obj = write(tmp_path, "box.obj", OBJ_WITH_TEXTURE)
    if with_library:
        write(tmp_path, "box.mtl", "newmtl skin\nKd 1 1 1\nmap_Kd -s 1 1 1 skin.png\n")
    if with_image:
        from PIL import Image

        Image.new("RGB", (8, 8), (200, 30, 30)).save(tmp_path / "skin.png")
    return obj


def test_an_obj_whose_texture_file_is_missing_is_refused_by_name(tmp_path):
    path = _textured_obj(tmp_path, with_image=False)
    with pytest.raises(MeshError, match="'skin.png', which does not exist") as info:
        load_mesh(path)
    assert str(path) in str(info.value) and "\n" not in str(info.value)
    # on request it goes in untextured
    mesh = load_mesh(path, options=LoadOptions(allow_missing_textures=True))
    assert mesh.n_faces == 4


def test_an_obj_whose_material_library_is_missing_is_refused(tmp_path):
    path = _textured_obj(tmp_path, with_library=False, with_image=False)
    with pytest.raises(MeshError, match="'box.mtl'"):
        load_mesh(path)


def test_an_obj_with_its_texture_present_loads_textured(tmp_path):
    path = _textured_obj(tmp_path)
    assert missing_textures(path) == []
    mesh = load_mesh(path)
    assert {g.visual.kind for g in mesh.scene.geometry.values()} == {"texture"}


def test_a_gltf_whose_image_file_is_missing_is_refused(tmp_path):
    import json

    from PIL import Image

    files = load_mesh(sample("car")).scene.export(file_type="gltf")
    for name, data in files.items():
        (tmp_path / name).write_bytes(data)
    doc = json.loads(files["model.gltf"])
    assert doc.get("images"), "the sample car is textured"
    doc["images"][0] = {"uri": "paint%20job.png"}  # an external image file (URI-escaped name)
    (tmp_path / "model.gltf").write_text(json.dumps(doc))
    Image.new("RGB", (8, 8), (10, 200, 30)).save(tmp_path / "paint job.png")
    assert missing_textures(tmp_path / "model.gltf") == []
    assert load_mesh(tmp_path / "model.gltf").n_faces > 0
    (tmp_path / "paint job.png").unlink()
    with pytest.raises(MeshError, match="'paint%20job.png', which does not exist"):
        load_mesh(tmp_path / "model.gltf")


def test_sample_and_shared_meshes_name_no_missing_texture():
    assert [p for p in sample_files() if missing_textures(p)] == []


def test_a_mesh_over_the_face_cap_is_refused_with_its_count(tmp_path):
    path = sample("chair")
    faces = load_mesh(path).n_faces
    with pytest.raises(MeshError, match=f"has {faces:,} triangles, more than the cap of {faces - 1:,}"):
        load_mesh(path, options=LoadOptions(max_faces=faces - 1))
    assert load_mesh(path, options=LoadOptions(max_faces=faces)).n_faces == faces
    assert load_mesh(path, options=LoadOptions(max_faces=None)).n_faces == faces
    with pytest.raises(ValueError):
        LoadOptions(max_faces=0)


def test_every_sample_declares_the_faces_it_loads_with():
    from viewdb.catalogue.mesh import _face_count, declared_faces

    for path in sample_files():
        assert declared_faces(path) == _face_count(trimesh.load(path, process=False)), path.name


def test_a_mesh_over_the_face_cap_is_refused_before_it_is_read_whole(tmp_path):
    """A header declaring two billion faces is refused from the header (loading it whole
    would allocate them); an OBJ's faces are counted streaming its lines."""
    ply = tmp_path / "huge.ply"
    ply.write_bytes(b"ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\n"
                    b"property float y\nproperty float z\nelement face 2000000000\n"
                    b"property list uchar int vertex_indices\nend_header\n" + b"\0" * 64)
    off = tmp_path / "huge.off"
    off.write_text("OFF\n# a comment\n3 2000000000 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n")
    stl = tmp_path / "huge.stl"
    stl.write_bytes(b"\0" * 80 + (3).to_bytes(4, "little") + b"\0" * 150)
    obj = tmp_path / "many.obj"
    obj.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\n" + "f 1 2 3 4\n" * 600)
    for path, faces in ((ply, 2_000_000_000), (off, 2_000_000_000), (obj, 1200)):
        with pytest.raises(MeshError, match=f"has {faces:,} triangles, more than the cap of 1,000"):
            load_mesh(path, options=LoadOptions(max_faces=1000))
    with pytest.raises(MeshError, match="has 3 triangles, more than the cap of 2"):
        load_mesh(stl, options=LoadOptions(max_faces=2))
