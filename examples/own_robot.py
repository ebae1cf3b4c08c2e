"""Connect your own robot: the robot side of the bridge protocol (docs/hil.md). BridgePlant.fmu
sends each step's joint torques here and goes on with the sensor values this script answers.
Replace the lines marked ROBOT with your robot's driver; our plant model stands in for it here.

    python examples/own_robot.py PORT TOKEN_FILE   # a new token is written if the file is missing
"""

import socket
import sys

from bridge_model import protocol
from plant_model.model import PlantModel

port, token_file = int(sys.argv[1]), sys.argv[2]
key, _ = protocol.token_file_key(token_file)  # the session token's key (file mode 600)
params = [v for v in PlantModel.variables() if v.causality == "parameter"]  # INIT's order
sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
sock.bind(("127.0.0.1", port))  # loopback only: see the trust model
print(f"robot: listening on 127.0.0.1:{port}", flush=True)
robot, last = None, (None, None, b"")
while True:
    data, bridge = sock.recvfrom(protocol.MAX_DATAGRAM)
    try:
        msg = protocol.Message(data, key)  # checks length, header and MAC
    except protocol.ProtocolError:
        continue  # not from our bridge: no answer
    if (msg.session, msg.seq) == last[:2]:  # a resent request: the same reply, no second step
        sock.sendto(last[2], bridge)
        continue
    if msg.kind == protocol.INIT:  # the plant's parameter values: (re)start the robot
        values = {v.name: {"Integer": int, "Boolean": bool}.get(v.type, float)(x)
                  for v, x in zip(params, msg.values, strict=True)}  # fmt: skip
        robot, kind = PlantModel(values, msg.t), protocol.INIT_REPLY  # ROBOT: connect, home
    elif msg.kind == protocol.STEP and robot is not None and msg.finite():
        robot.do_step(msg.t, msg.h, msg.values)  # ROBOT: apply tau1..3 for h seconds
        kind = protocol.STEP_REPLY
    else:
        continue
    outputs = robot.outputs()  # ROBOT: read q1..q3, the wrist force sensor, ... (20 values)
    reply = protocol.pack(key, kind, msg.seq, msg.session, robot.t, msg.h, outputs,
                          echo_ns=msg.stamp_ns)  # fmt: skip
    last = (msg.session, msg.seq, reply)
    sock.sendto(reply, bridge)
