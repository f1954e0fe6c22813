"""A fly-around as a ROS 2 bag (rosbag2, MCAP storage), written with the ``rosbags`` library (no
ROS install): what ROS 2 tools, Foxglove and rosbags' own reader open.

Topics, one message per frame, stamped at ``orbit.epoch_utc`` + the frame's ``t_s``:

- ``/lidar/points`` (``sensor_msgs/msg/PointCloud2``, frame ``lidar``): the frame's points, one
  row of ``width`` = n points, little-endian, fields x, y, z [m], intensity [W], range [m], snr,
  part_id, range_error_m [m] and outlier (0/1), each in the cloud's own precision (FLOAT64 for
  float64 values, INT32, UINT8), so the values read back bit for bit;
- ``/tf`` (``tf2_msgs/msg/TFMessage``): the true T_sensor_target, parent ``lidar``, child
  ``target`` (ROS's quaternion fields x, y, z, w: the same active Hamilton rotation);
- ``/tracking/pose`` (``geometry_msgs/msg/PoseStamped``, frame ``lidar``): the estimated pose of
  the target when the fly-around was tracked.

The bag is one ``.mcap`` file (rosbags' reader and ROS 2 open the file itself), written atomically.
"""

from __future__ import annotations

import datetime
import os
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from .orbit.epoch import parse_utc

__all__ = ["FIELDS", "POINTS_TOPIC", "POSE_TOPIC", "TF_TOPIC", "cloud_array", "write_bag"]

POINTS_TOPIC = "/lidar/points"
TF_TOPIC = "/tf"
POSE_TOPIC = "/tracking/pose"
SENSOR_FRAME = "lidar"
TARGET_FRAME = "target"
# PointCloud2 field name -> the cloud's attribute (None: the point's coordinate)
FIELDS = {
    "x": None,
    "y": None,
    "z": None,
    "intensity": "intensity_w",
    "range": "range_m",
    "snr": "snr",
    "part_id": "part_id",
    "range_error_m": "range_error_m",
    "outlier": "outlier",
}
# numpy dtype -> sensor_msgs/PointField datatype
_DATATYPES = {"i1": 1, "u1": 2, "i2": 3, "u2": 4, "i4": 5, "u4": 6, "f4": 7, "f8": 8}


def cloud_array(cloud: Any) -> np.ndarray:
    """The cloud's points as one structured array (n,) of the FIELDS, little-endian (booleans as
    uint8): the rows of its PointCloud2."""
    columns = {}
    for k, (name, attribute) in enumerate(FIELDS.items()):
        values = cloud.points[:, k] if attribute is None else cloud.attributes[attribute]
        values = np.asarray(values)
        if values.dtype == np.bool_:
            values = values.astype(np.uint8)
        columns[name] = values.astype(values.dtype.newbyteorder("<"))
    dtype = np.dtype([(name, v.dtype) for name, v in columns.items()])
    out = np.empty(len(cloud.points), dtype=dtype)
    for name, values in columns.items():
        out[name] = values
    return out


def _stamp(types: Any, ns: int) -> Any:
    return types["builtin_interfaces/msg/Time"](sec=ns // 10**9, nanosec=ns % 10**9)


def _header(types: Any, ns: int, frame: str) -> Any:
    return types["std_msgs/msg/Header"](stamp=_stamp(types, ns), frame_id=frame)


def _point_cloud(types: Any, ns: int, cloud: Any) -> Any:
    rows = cloud_array(cloud)
    field = types["sensor_msgs/msg/PointField"]
    layout: dict[str, Any] = dict(rows.dtype.fields or {})
    fields = [
        field(name=name, offset=offset, datatype=_DATATYPES[dtype.str[1:]], count=1)
        for name, (dtype, offset, *_) in layout.items()
    ]
    return types["sensor_msgs/msg/PointCloud2"](
        header=_header(types, ns, SENSOR_FRAME),
        height=1,
        width=len(rows),
        fields=fields,
        is_bigendian=False,
        point_step=rows.dtype.itemsize,
        row_step=rows.dtype.itemsize * len(rows),
        data=np.frombuffer(rows.tobytes(), dtype=np.uint8),
        is_dense=False,
    )


def _pose_parts(types: Any, translation, quaternion_wxyz) -> tuple[Any, Any]:
    w, x, y, z = (float(v) for v in quaternion_wxyz)
    q = types["geometry_msgs/msg/Quaternion"](x=x, y=y, z=z, w=w)
    return [float(v) for v in translation], q


def _tf(types: Any, ns: int, translation, quaternion_wxyz) -> Any:
    (tx, ty, tz), q = _pose_parts(types, translation, quaternion_wxyz)
    transform = types["geometry_msgs/msg/Transform"](
        translation=types["geometry_msgs/msg/Vector3"](x=tx, y=ty, z=tz), rotation=q
    )
    stamped = types["geometry_msgs/msg/TransformStamped"](
        header=_header(types, ns, SENSOR_FRAME), child_frame_id=TARGET_FRAME, transform=transform
    )
    return types["tf2_msgs/msg/TFMessage"](transforms=[stamped])


def _pose(types: Any, ns: int, translation, quaternion_wxyz) -> Any:
    (px, py, pz), q = _pose_parts(types, translation, quaternion_wxyz)
    pose = types["geometry_msgs/msg/Pose"](
        position=types["geometry_msgs/msg/Point"](x=px, y=py, z=pz), orientation=q
    )
    return types["geometry_msgs/msg/PoseStamped"](
        header=_header(types, ns, SENSOR_FRAME), pose=pose
    )


def frame_stamps_ns(epoch_utc: str, t_s) -> list[int]:
    """Nanoseconds since the Unix epoch of each frame (``epoch_utc`` + ``t_s`` [s])."""
    epoch = parse_utc("orbit.epoch_utc", epoch_utc)
    unix = datetime.datetime(1970, 1, 1, tzinfo=datetime.UTC)
    base_ns = round((epoch - unix).total_seconds()) * 10**9
    return [base_ns + round(float(t) * 1e9) for t in t_s]


def write_bag(path: str | Path, fly: Any, tracked: Any = None) -> Path:
    """Write the fly-around ``fly`` (a ``FlyaroundResult`` with its clouds) as one MCAP file.

    Parameters
    ----------
    path : str or Path
        The ``.mcap`` file; its folder must exist. Replaced atomically.
    fly : FlyaroundResult
        Run with ``keep_clouds=True``.
    tracked : TrackResult, optional
        The estimated poses, on ``/tracking/pose``.

    Returns
    -------
    Path
        ``path``.
    """
    from rosbags.rosbag2 import StoragePlugin, Writer  # noqa: PLC0415
    from rosbags.typesys import Stores, get_typestore  # noqa: PLC0415

    path = Path(path)
    if not fly.clouds:
        raise ValueError("write_bag needs the clouds: run_flyaround(..., keep_clouds=True)")
    store = get_typestore(Stores.ROS2_HUMBLE)
    types = store.types
    stamps = frame_stamps_ns(fly.scene.orbit.epoch_utc, fly.truth.t_s)
    with tempfile.TemporaryDirectory(dir=path.parent, prefix=f".{path.name}.") as tmp:
        folder = Path(tmp) / "bag"
        with Writer(folder, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
            topics = [
                (POINTS_TOPIC, "sensor_msgs/msg/PointCloud2"),
                (TF_TOPIC, "tf2_msgs/msg/TFMessage"),
            ]
            if tracked is not None:
                topics.append((POSE_TOPIC, "geometry_msgs/msg/PoseStamped"))
            conn = {t: writer.add_connection(t, m, typestore=store) for t, m in topics}
            for i, ns in enumerate(stamps):
                messages = [
                    (POINTS_TOPIC, _point_cloud(types, ns, fly.clouds[i])),
                    (
                        TF_TOPIC,
                        _tf(types, ns, fly.truth.translation_m[i], fly.truth.quaternion_wxyz[i]),
                    ),
                ]
                if tracked is not None:
                    est = tracked.poses[i]
                    q = tracked.quaternion_wxyz[i]
                    messages.append((POSE_TOPIC, _pose(types, ns, est[:3, 3], q)))
                for topic, message in messages:
                    msgtype = dict(topics)[topic]
                    writer.write(conn[topic], ns, store.serialize_cdr(message, msgtype))
        os.replace(folder / "bag.mcap", path)
    return path
