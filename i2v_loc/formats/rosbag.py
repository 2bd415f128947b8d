"""ROS bags through ``rosbags``: rosbag2 (sqlite3 and MCAP storage) and ROS 1 bags with
``sensor_msgs/PointCloud2``, one topic per sensor; extrinsics from ``/tf_static`` (or sensors.yaml).

Written layout (``write_bag``): topic ``/<sensor>/points``, ``header.frame_id`` = the sensor,
``header.stamp`` = sweep start on the sensor's clock, fields ``x y z`` float32 and ``t`` uint32 (ns
after the stamp, as the Ouster ROS driver publishes), one message per sweep; ``/tf_static`` holds
``yard`` → sensor for every sensor. The parameter file and the ground truth sit in the bag folder.
MCAP bags are written with the ``mcap`` library (rosbags 0.9, pinned by ouster-sdk, writes only
sqlite3) and read by rosbags like any rosbag2.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import yaml

from i2v_loc.formats.base import FormatError, PointRecording, copy_side_files
from i2v_loc.frame import SensorScan

WORLD_FRAME = "yard"
POINTCLOUD2 = "sensor_msgs/msg/PointCloud2"
TF_STATIC = "/tf_static"
# sensor_msgs/PointField datatypes
FIELD_DTYPES = {1: "i1", 2: "u1", 3: "i2", 4: "u2", 5: "i4", 6: "u4", 7: "f4", 8: "f8"}


def _typestore():
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS2_HUMBLE)


def topic_of(sensor: str) -> str:
    return f"/{sensor}/points"


def sensor_of(topic: str) -> str:
    name = topic.strip("/").removesuffix("/points").removesuffix("points").strip("/") or "lidar"
    return name.replace("/", "_")


def is_bag(path: Path) -> bool:
    if path.is_dir():
        return (path / "metadata.yaml").is_file()
    return path.suffix in (".bag", ".db3", ".mcap") and path.is_file()


# --------------------------------------------------------------------------- writing


def cloud_message(store, sensor: str, stamp_ns: int, points: np.ndarray, offsets_s: np.ndarray):
    msgs = store.types
    Header, Time = msgs["std_msgs/msg/Header"], msgs["builtin_interfaces/msg/Time"]
    PointField, PointCloud2 = msgs["sensor_msgs/msg/PointField"], msgs[POINTCLOUD2]
    data = np.zeros(len(points), dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("t", "<u4")])
    data["x"], data["y"], data["z"] = points[:, 0], points[:, 1], points[:, 2]
    data["t"] = np.rint(np.asarray(offsets_s, dtype=np.float64) * 1e9).astype(np.uint32)
    sec, nanosec = divmod(int(stamp_ns), 1_000_000_000)
    fields = [
        PointField(name=n, offset=o, datatype=d, count=1)
        for n, o, d in (("x", 0, 7), ("y", 4, 7), ("z", 8, 7), ("t", 12, 6))
    ]
    return PointCloud2(
        header=Header(stamp=Time(sec=sec, nanosec=nanosec), frame_id=sensor),
        height=1,
        width=len(points),
        fields=fields,
        is_bigendian=False,
        point_step=16,
        row_step=16 * len(points),
        data=data.view(np.uint8).reshape(-1),
        is_dense=True,
    )


def tf_static_message(store, sensors: list[dict]):
    from scipy.spatial.transform import Rotation

    msgs = store.types
    Header, Time = msgs["std_msgs/msg/Header"], msgs["builtin_interfaces/msg/Time"]
    transforms = []
    for sensor in sensors:
        e = sensor.get("extrinsics") or {}
        q = Rotation.from_euler(
            "ZYX", [e.get("yaw_deg", 0.0), e.get("pitch_deg", 0.0), e.get("roll_deg", 0.0)], degrees=True
        ).as_quat()
        transforms.append(
            msgs["geometry_msgs/msg/TransformStamped"](
                header=Header(stamp=Time(sec=0, nanosec=0), frame_id=WORLD_FRAME),
                child_frame_id=sensor["name"],
                transform=msgs["geometry_msgs/msg/Transform"](
                    translation=msgs["geometry_msgs/msg/Vector3"](
                        x=e.get("x_m", 0.0), y=e.get("y_m", 0.0), z=e.get("z_m", 0.0)
                    ),
                    rotation=msgs["geometry_msgs/msg/Quaternion"](x=q[0], y=q[1], z=q[2], w=q[3]),
                ),
            )
        )
    return msgs["tf2_msgs/msg/TFMessage"](transforms=transforms)


def _bag_messages(recording):
    """(topic, msgtype, log time ns, message) of a native recording, in log-time order."""
    store = _typestore()
    sensors_yaml = yaml.safe_load(recording.sensors_file.read_text()) if recording.sensors_file.is_file() else {}
    sensors = [s for s in (sensors_yaml or {}).get("sensors", []) if s.get("name") in recording.sensor_names]
    # log times > 0: rosbags skips MCAP chunks that start at time 0
    items = [(TF_STATIC, "tf2_msgs/msg/TFMessage", 1, tf_static_message(store, sensors))] if sensors else []
    period_ns = int(round(1e9 / recording.rate_hz))
    for name in recording.sensor_names:
        scans = recording.scans(name)
        for k in range(scans.n_frames):
            points, offsets = scans.points(k)
            stamp = int(scans.stamp_ns[k])
            items.append(
                (
                    topic_of(name),
                    POINTCLOUD2,
                    max(stamp + period_ns, 1),
                    cloud_message(store, name, stamp, points, offsets),
                )
            )
    items.sort(key=lambda item: item[2])
    return store, items


def write_bag(recording, out: str | Path, storage: str = "sqlite3") -> Path:
    """A rosbag2 folder (sqlite3 or MCAP storage) with the recording's sweeps and /tf_static."""
    store, items = _bag_messages(recording)
    write_items(out, store, items, storage)
    copy_side_files(recording, out)
    return out


def write_states_bag(states: list[dict], out: str | Path, storage: str = "sqlite3") -> Path:
    """State lines as ``std_msgs/msg/String`` (the JSON line) on ``/i2v_loc/states``, logged at
    their ``stamp_s`` (frames without a stamp at the previous one)."""
    import json

    store = _typestore()
    String = store.types["std_msgs/msg/String"]
    items, last_ns = [], 1
    for line in states:
        if line.get("stamp_s") is not None:
            last_ns = max(int(round(line["stamp_s"] * 1e9)), 1)
        items.append(
            (STATES_TOPIC, "std_msgs/msg/String", last_ns, String(data=json.dumps(line, separators=(",", ":"))))
        )
    write_items(out, store, items, storage)
    return Path(out)


STATES_TOPIC = "/i2v_loc/states"


def write_items(out: str | Path, store, items, storage: str) -> None:
    from rosbags.rosbag2 import Writer

    out = Path(out)
    if out.exists() and (not out.is_dir() or any(out.iterdir())):
        raise FormatError(f"{out}: exists and is not an empty folder; a bag is written into a new folder")
    if out.exists():
        out.rmdir()
    with Writer(out) as writer:
        connections = {}
        for topic, msgtype, _, _ in items:
            if topic not in connections:
                qos = _LATCHED_QOS if topic == TF_STATIC else ""
                connections[topic] = writer.add_connection(topic, msgtype, typestore=store, offered_qos_profiles=qos)
        for topic, msgtype, stamp, msg in items:
            writer.write(connections[topic], stamp, store.serialize_cdr(msg, msgtype))
    if storage == "mcap":
        _sqlite_to_mcap(out, store, items)


_LATCHED_QOS = (
    "- history: 3\n  depth: 0\n  reliability: 1\n  durability: 1\n  deadline:\n    sec: 2147483647\n"
    "    nsec: 4294967295\n  lifespan:\n    sec: 2147483647\n    nsec: 4294967295\n  liveliness: 1\n"
    "  liveliness_lease_duration:\n    sec: 2147483647\n    nsec: 4294967295\n  avoid_ros_namespace_conventions: false"
)


def _sqlite_to_mcap(out: Path, store, items) -> None:
    """Rewrite the bag's storage as MCAP (ros2msg schemas, CDR messages), metadata.yaml updated."""
    from mcap.writer import Writer as McapWriter

    meta_file = out / "metadata.yaml"
    meta = yaml.safe_load(meta_file.read_text())
    info = meta["rosbag2_bagfile_information"]
    db3 = out / info["relative_file_paths"][0]
    mcap_name = f"{out.name}.mcap"
    with open(out / mcap_name, "wb") as fh:
        writer = McapWriter(fh)
        writer.start(profile="ros2", library="i2v-loc")
        channels = {}
        for topic, msgtype, _, _ in items:
            if topic in channels:
                continue
            schema = writer.register_schema(name=msgtype, encoding="ros2msg", data=_msgdef(store, msgtype).encode())
            qos = _LATCHED_QOS if topic == TF_STATIC else ""
            channels[topic] = writer.register_channel(
                topic=topic, message_encoding="cdr", schema_id=schema, metadata={"offered_qos_profiles": qos}
            )
        for sequence, (topic, msgtype, stamp, msg) in enumerate(items):
            writer.add_message(
                channel_id=channels[topic],
                log_time=stamp,
                publish_time=stamp,
                sequence=sequence,
                data=bytes(store.serialize_cdr(msg, msgtype)),
            )
        writer.finish()
    db3.unlink()
    info["storage_identifier"] = "mcap"
    info["relative_file_paths"] = [mcap_name]
    for file in info.get("files", []):
        file["path"] = mcap_name
    meta_file.write_text(yaml.safe_dump(meta, sort_keys=False))


def _msgdef(store, msgtype: str) -> str:
    """The ROS 2 message definition with its dependencies, as ``ros2 bag`` stores it in MCAP."""
    return store.generate_msgdef(msgtype, ros_version=2)[0]


# --------------------------------------------------------------------------- reading


def cloud_points(msg, where: str) -> tuple[np.ndarray, np.ndarray]:
    """Finite points (N, 3) float32 and their time offsets (N,) in s after the header stamp."""
    names = {f.name: f for f in msg.fields}
    missing = [n for n in ("x", "y", "z") if n not in names]
    if missing:
        raise FormatError(f"{where}: PointCloud2 without the fields {missing} (has {list(names)})")
    order = ">" if msg.is_bigendian else "<"
    wanted = [n for n in ("x", "y", "z", "t", "time", "timestamp") if n in names]
    for n in wanted:
        if names[n].datatype not in FIELD_DTYPES:
            raise FormatError(f"{where}: PointCloud2 field {n!r} has unknown datatype {names[n].datatype}")
    dtype = np.dtype(
        {
            "names": wanted,
            "formats": [order + FIELD_DTYPES[names[n].datatype] for n in wanted],
            "offsets": [names[n].offset for n in wanted],
            "itemsize": msg.point_step,
        }
    )
    count = msg.width * msg.height
    raw = np.asarray(msg.data, dtype=np.uint8)
    if len(raw) < count * msg.point_step:
        raise FormatError(f"{where}: PointCloud2 data has {len(raw)} bytes for {count} points of {msg.point_step}")
    cloud = np.frombuffer(raw[: count * msg.point_step].tobytes(), dtype=dtype, count=count)
    xyz = np.stack([cloud["x"], cloud["y"], cloud["z"]], axis=1).astype(np.float64)
    if "t" in wanted:  # Ouster driver: uint32 ns after the stamp
        offsets = cloud["t"].astype(np.float64) * 1e-9
    elif wanted[-1] in ("time", "timestamp"):
        offsets = cloud[wanted[-1]].astype(np.float64)
        stamp_s = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9
        if np.nanmax(np.abs(offsets), initial=0.0) > 1e6:  # absolute times (Velodyne/Hesai drivers)
            offsets = offsets - stamp_s
    else:
        offsets = np.zeros(count)
    finite = np.isfinite(xyz).all(axis=1) & ~(xyz == 0).all(axis=1)
    return xyz[finite].astype(np.float32), offsets[finite].astype(np.float32)


class BagRecording(PointRecording):
    """A rosbag2 folder (sqlite3 / MCAP) or a ROS 1 ``.bag``; frame k = the k-th sweep of each sensor."""

    layout = "rosbag2"

    def __init__(self, path: str | Path, topics: dict[str, str] | None = None):
        from rosbags.highlevel import AnyReader, AnyReaderError

        path = Path(path)
        bag_path = (
            path.parent if path.suffix in (".db3", ".mcap") and (path.parent / "metadata.yaml").is_file() else path
        )
        self.layout = "rosbag2" if bag_path.is_dir() else "rosbag1"
        self._sweeps: dict[str, list[SensorScan]] = {}
        self._tf: dict[str, dict] = {}
        try:
            with AnyReader([bag_path], default_typestore=_typestore()) as reader:
                clouds = {c.topic: c for c in reader.connections if c.msgtype == POINTCLOUD2}
                wanted = self._choose_topics(bag_path, sorted(clouds), topics)
                for name in wanted:
                    self._sweeps[name] = []
                for conn, _, raw in reader.messages(connections=[clouds[t] for t in wanted.values()]):
                    msg = reader.deserialize(raw, conn.msgtype)
                    name = next(n for n, t in wanted.items() if t == conn.topic)
                    pts, off = cloud_points(msg, f"{bag_path}: {conn.topic}")
                    stamp = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9
                    self._sweeps[name].append(SensorScan(sensor=name, stamp_s=stamp, points=pts, time_offset_s=off))
                tf_conns = [c for c in reader.connections if c.topic == TF_STATIC]
                for conn, _, raw in reader.messages(connections=tf_conns) if tf_conns else ():  # [] means all
                    for tf in reader.deserialize(raw, conn.msgtype).transforms:
                        self._tf[tf.child_frame_id] = _tf_extrinsics(tf)
        except FormatError:
            raise
        except (
            AnyReaderError,
            Exception,
        ) as err:  # rosbags, sqlite3 and the MCAP parser raise many kinds on corrupt bags
            raise FormatError(f"{bag_path}: cannot read the bag: {' '.join(str(err).split())[:300]}") from None
        for name, sweeps in self._sweeps.items():
            if not sweeps:
                raise FormatError(f"{bag_path}: topic {wanted[name]} of sensor {name} has no messages")
            sweeps.sort(key=lambda s: s.stamp_s)
        rate = _rate_hz([s.stamp_s for s in next(iter(self._sweeps.values()))])
        super().__init__(bag_path, list(self._sweeps), max(len(s) for s in self._sweeps.values()), rate)
        self.meta["topics"] = dict(wanted)

    def _choose_topics(self, bag_path: Path, clouds: list[str], topics: dict[str, str] | None) -> dict[str, str]:
        if not clouds:
            raise FormatError(f"{bag_path}: no {POINTCLOUD2} topic in the bag")
        if topics:
            missing = {n: t for n, t in topics.items() if t not in clouds}
            if missing:
                name, topic = next(iter(missing.items()))
                raise FormatError(
                    f"{bag_path}: no PointCloud2 topic {topic} (sensor {name}); the bag has {', '.join(clouds)}"
                )
            return dict(topics)
        configured = _configured_sensors(bag_path)
        if configured:
            missing = [n for n in configured if topic_of(n) not in clouds]
            if missing:
                raise FormatError(
                    f"{bag_path}: no PointCloud2 topic {topic_of(missing[0])} for sensor {missing[0]} of "
                    f"sensors.yaml; the bag has {', '.join(clouds)}"
                )
            return {n: topic_of(n) for n in configured}
        return {sensor_of(t): t for t in clouds}

    def _scan(self, sensor: str, index: int) -> SensorScan | None:
        sweeps = self._sweeps[sensor]
        return sweeps[index] if index < len(sweeps) else None

    def generated_sensors(self) -> list[dict] | None:
        """The sensors with their extrinsics from /tf_static (only sensors it has a transform for)."""
        known = [n for n in self.sensor_names if n in self._tf]
        if not known:
            return None
        return [{"name": n, "rate_hz": int(round(self.rate_hz)), "extrinsics": self._tf[n]} for n in known]


def _configured_sensors(bag_path: Path) -> list[str]:
    file = bag_path / "sensors.yaml" if bag_path.is_dir() else bag_path.parent / "sensors.yaml"
    if not file.is_file():
        return []
    data = yaml.safe_load(file.read_text()) or {}
    return [s["name"] for s in data.get("sensors", []) if isinstance(s, dict) and "name" in s]


def _tf_extrinsics(tf) -> dict:
    from scipy.spatial.transform import Rotation

    r, t = tf.transform.rotation, tf.transform.translation
    yaw, pitch, roll = Rotation.from_quat([r.x, r.y, r.z, r.w]).as_euler("ZYX", degrees=True)
    return {
        "x_m": float(t.x),
        "y_m": float(t.y),
        "z_m": float(t.z),
        "roll_deg": round(float(roll), 9),
        "pitch_deg": round(float(pitch), 9),
        "yaw_deg": round(float(yaw), 9),
    }


def _rate_hz(stamps: list[float]) -> float:
    if len(stamps) < 2:
        return 10.0
    period = float(np.median(np.diff(stamps)))
    return round(1.0 / period, 3) if period > 0 and math.isfinite(period) else 10.0
