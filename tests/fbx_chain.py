"""An ASCII FBX file of a bone chain, written by hand: hostile depths for the FBX reader's tests."""

from __future__ import annotations

KTIME_PER_S = 46186158000


def chain_fbx(bones: int, take_s: float = 1.0) -> str:
    """``bones`` LimbNodes, each the child of the one before, 10 units apart; a take of
    ``take_s`` seconds turning the second bone by 90 degrees."""
    stop = round(take_s * KTIME_PER_S)
    out = ["; FBX 7.4.0 project file\nFBXHeaderExtension:  {\n\tFBXVersion: 7400\n}\nObjects:  {\n"]
    for k in range(bones):
        out.append(
            f'\tNodeAttribute: {2000000 + k}, "NodeAttribute::", "LimbNode" {{\n\t\tTypeFlags: "Skeleton"\n\t}}\n'
        )
        out.append(
            f'\tModel: {1000000 + k}, "Model::b{k}", "LimbNode" {{\n\t\tVersion: 232\n\t\tProperties70:  {{\n'
            f'\t\t\tP: "Lcl Translation", "Lcl Translation", "", "A",0,10,0\n\t\t}}\n\t}}\n'
        )
    out.append(
        f'\tAnimationStack: 3000, "AnimStack::Take", "" {{\n\t\tProperties70:  {{\n'
        f'\t\t\tP: "LocalStart", "KTime", "Time", "",0\n\t\t\tP: "LocalStop", "KTime", "Time", "",{stop}\n'
        f'\t\t\tP: "ReferenceStop", "KTime", "Time", "",{stop}\n\t\t}}\n\t}}\n'
        '\tAnimationLayer: 3001, "AnimLayer::BaseLayer", "" {\n\t}\n'
        '\tAnimationCurveNode: 4000, "AnimCurveNode::R", "" {\n\t\tProperties70:  {\n'
        '\t\t\tP: "d|X", "Number", "", "A",0\n\t\t\tP: "d|Y", "Number", "", "A",0\n'
        '\t\t\tP: "d|Z", "Number", "", "A",0\n\t\t}\n\t}\n'
        '\tAnimationCurve: 5000, "AnimCurve::", "" {\n\t\tDefault: 0\n\t\tKeyVer: 4009\n'
        f"\t\tKeyTime: *2 {{\n\t\t\ta: 0,{stop}\n\t\t}}\n\t\tKeyValueFloat: *2 {{\n\t\t\ta: 0,90\n\t\t}}\n"
        "\t\tKeyAttrFlags: *1 {\n\t\t\ta: 4\n\t\t}\n\t\tKeyAttrDataFloat: *4 {\n\t\t\ta: 0,0,0,0\n\t\t}\n"
        "\t\tKeyAttrRefCount: *1 {\n\t\t\ta: 2\n\t\t}\n\t}\n}\nConnections:  {\n"
    )
    for k in range(bones):
        out.append(f'\tC: "OO",{1000000 + k},{1000000 + k - 1 if k else 0}\n')
        out.append(f'\tC: "OO",{2000000 + k},{1000000 + k}\n')
    target = 1000001 if bones > 1 else 1000000
    out.append(
        '\tC: "OO",3001,3000\n\tC: "OO",4000,3001\n'
        f'\tC: "OP",4000,{target}, "Lcl Rotation"\n\tC: "OP",5000,4000, "d|Z"\n}}\n'
    )
    return "".join(out)
