"""The paper's grasp demo, built on the framework: the MuJoCo rod and KR6 R700 scene, the
OpenCV camera, the DDPG policy, EthernetKRL, the trials, their configs and commands.

Nothing outside this package imports it, but the command line registering its commands; the
node loader finds its models through the ``hycosim.models`` entry points.
"""
