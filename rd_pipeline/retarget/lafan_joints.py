"""LAFAN1 joints with a role in retargeting; the robot side uses whichever bodies the config maps to them."""

PELVIS = "Hips"
TORSO = "Spine2"
FEET = ("LeftFoot", "RightFoot")
KNEES = ("LeftLeg", "RightLeg")
TOES = ("LeftToe", "RightToe")
HIPS_LR = ("LeftUpLeg", "RightUpLeg")
SHOULDERS_LR = ("LeftArm", "RightArm")
LOWER_SPINE = "Spine"
