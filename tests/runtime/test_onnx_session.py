import json

import pytest

from spacepose.errors import BundleError
from spacepose.onnx_session import METADATA_KEY, make_session, read_metadata, session_metadata, write_metadata


def test_missing_file(tmp_path):
    with pytest.raises(BundleError, match="not found"):
        make_session(tmp_path / "nope.onnx")


def test_corrupt_file(tmp_path):
    bad = tmp_path / "bad.onnx"
    bad.write_bytes(b"this is not a protobuf")
    with pytest.raises(BundleError, match="cannot load"):
        make_session(bad)


def test_session_options_and_metadata(tiny_stereo_graph):
    sess = make_session(tiny_stereo_graph, threads=1, mem_arena=False)
    meta = session_metadata(sess)
    assert meta["kind"] == "stereo" and meta["input_size"] == [64, 64] and meta["iters"] == 2
    assert read_metadata(tiny_stereo_graph) == meta
    opts = sess.get_session_options()
    assert opts.intra_op_num_threads == 1 and not opts.enable_cpu_mem_arena
    # workers sleep between runs, so the pipeline's numpy work between graph calls keeps its cores
    assert opts.get_session_config_entry("session.intra_op.allow_spinning") == "0"
    spinning = make_session(tiny_stereo_graph, threads=1, spinning=True).get_session_options()
    assert spinning.get_session_config_entry("session.intra_op.allow_spinning") == "1"
    # ...but only inside run(): they stop spinning when it returns
    assert spinning.get_session_config_entry("session.force_spinning_stop") == "1"


def test_graph_without_contract_is_refused(tmp_path):
    onnx = pytest.importorskip("onnx")
    from onnx import TensorProto, helper

    node = helper.make_node("Identity", ["x"], ["y"])
    graph = helper.make_graph([node], "g", [helper.make_tensor_value_info("x", TensorProto.FLOAT, [1])],
                              [helper.make_tensor_value_info("y", TensorProto.FLOAT, [1])])
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    model.ir_version = 8
    path = tmp_path / "plain.onnx"
    onnx.save(model, str(path))
    with pytest.raises(BundleError, match="no 'spacepose' metadata"):
        read_metadata(path)
    write_metadata(model, {"kind": "x", "n": 1})
    write_metadata(model, {"kind": "y"})  # replaces, does not duplicate
    assert sum(p.key == METADATA_KEY for p in model.metadata_props) == 1
    onnx.save(model, str(path))
    assert read_metadata(path) == {"kind": "y"}
    model.metadata_props[0].value = "{not json"
    onnx.save(model, str(path))
    with pytest.raises(BundleError, match="not valid JSON"):
        read_metadata(path)
    model.metadata_props[0].value = json.dumps([1, 2])
    onnx.save(model, str(path))
    with pytest.raises(BundleError, match="JSON object"):
        read_metadata(path)
