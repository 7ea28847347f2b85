"""The PEMKRE vocabularies as rdflib :class:`DefinedNamespace` classes (typos fail at import time).

Each class mirrors one Turtle file under ``ontologies/``; ``test_vocab.py`` checks that both list the same terms.
``PREFIXES`` is the ``initNs`` every prepared query gets.
"""
from typing import Dict

from rdflib import Namespace, URIRef
from rdflib.namespace import OWL, RDF, RDFS, XSD, DefinedNamespace

BASE = "https://locem-bridge.example.org/"
#: Default namespace of world instances (scanned features, the robot, tools, locations).
SITE = Namespace(BASE + "site/")
#: Default namespace of specific processes and their task executions (the execution log).
LOG = Namespace(BASE + "log/")
#: Named graphs the store keeps apart (asserted vs inferred, schema vs world vs log).
GRAPHS = Namespace(BASE + "graph/")
#: The engine's bookkeeping (request ids of status reports and process starts): not in any ontology.
META = Namespace(BASE + "meta#")


class PROC(DefinedNamespace):
    """Process vocabulary: abstract/specific processes, flow nodes, transitions, tasks, parameters, effects, named queries (ontologies/process.ttl)."""

    _fail = True
    _NS = Namespace("https://locem-bridge.example.org/ont/process#")

    AbstractProcess: URIRef
    ControlNode: URIRef
    DecisionNode: URIRef
    Effect: URIRef
    EndNode: URIRef
    FlowNode: URIRef
    MergeNode: URIRef
    NamedQuery: URIRef
    Parameter: URIRef
    ProcessOption: URIRef
    ProcessStatus: URIRef
    ResultFormat: URIRef
    ScanResultJson: URIRef
    SpecificProcess: URIRef
    StartNode: URIRef
    Status: URIRef
    TaskExecution: URIRef
    TaskNode: URIRef
    TaskStatus: URIRef
    Transition: URIRef
    actionType: URIRef
    bindingQuery: URIRef
    condition: URIRef
    currentNode: URIRef
    currentTask: URIRef
    defaultValue: URIRef
    detail: URIRef
    durationSeconds: URIRef
    effectProperty: URIRef
    effectSubject: URIRef
    effectValue: URIRef
    endOutcome: URIRef
    ended: URIRef
    endedAt: URIRef
    executes: URIRef
    failed: URIRef
    hasEffect: URIRef
    hasNode: URIRef
    hasOption: URIRef
    hasParameter: URIRef
    hasParameterLiteral: URIRef
    hasParameterValue: URIRef
    hasTask: URIRef
    in_progress: URIRef
    incoming: URIRef
    involvesOperator: URIRef
    isManualFallback: URIRef
    issued: URIRef
    isWorldSeed: URIRef
    issuedAt: URIRef
    kpiByProcess: URIRef
    kpiByTaskType: URIRef
    nodeOf: URIRef
    onDetail: URIRef
    onStatus: URIRef
    onTaskFailure: URIRef
    optionName: URIRef
    optionProperty: URIRef
    orderedBy: URIRef
    outgoing: URIRef
    parameterProperty: URIRef
    partOfProcess: URIRef
    priority: URIRef
    queryName: URIRef
    queryText: URIRef
    queryVariable: URIRef
    realizes: URIRef
    required: URIRef
    resultFormat: URIRef
    running: URIRef
    selectsMemberOf: URIRef
    sequenceNumber: URIRef
    source: URIRef
    startNode: URIRef
    startedAt: URIRef
    status: URIRef
    statusName: URIRef
    subjectParameter: URIRef
    succeeded: URIRef
    target: URIRef
    taskCount: URIRef
    taskLog: URIRef
    taskType: URIRef
    valueParameter: URIRef


class PPR(DefinedNamespace):
    """PPR world-state vocabulary: walls, joint lines, areas, robot, tools, locations, processing states (ontologies/ppr.ttl)."""

    _fail = True
    _NS = Namespace("https://locem-bridge.example.org/ont/ppr#")

    HomeLocation: URIRef
    HorizontalJointLine: URIRef
    JointLine: URIRef
    Location: URIRef
    ProcessingState: URIRef
    Product: URIRef
    Resource: URIRef
    Robot: URIRef
    Sander: URIRef
    SandingPending: URIRef
    SandingReady: URIRef
    SprayGun: URIRef
    Sprayed: URIRef
    SprayingPending: URIRef
    TapingPending: URIRef
    TapingTool: URIRef
    Tool: URIRef
    VerticalJointLine: URIRef
    Wall: URIRef
    WallArea: URIRef
    WallFeature: URIRef
    atLocation: URIRef
    featureId: URIRef
    geometry: URIRef
    hasFeature: URIRef
    height: URIRef
    kind: URIRef
    lastScannedAt: URIRef
    manualRequired: URIRef
    mountedTool: URIRef
    onWall: URIRef
    processed: URIRef
    processedManually: URIRef
    processingStatus: URIRef
    sandingStatus: URIRef
    scanOrder: URIRef
    sprayingStatus: URIRef
    tapingStatus: URIRef
    thickness: URIRef
    unprocessed: URIRef
    validated: URIRef
    width: URIRef


class PLB(DefinedNamespace):
    """The plasterboard use case: task types, parameters, effects, the taping/spraying/sanding processes (ontologies/plasterboard.ttl)."""

    _fail = True
    _NS = Namespace("https://locem-bridge.example.org/ont/plasterboard#")

    GetToolTask: URIRef
    GoHomeTask: URIRef
    ManualTapingTask: URIRef
    RecoverTask: URIRef
    SandAreaTask: URIRef
    SandingProcess: URIRef
    ScanTask: URIRef
    SprayAreaTask: URIRef
    SprayingProcess: URIRef
    TapeLineTask: URIRef
    TapingProcess: URIRef
    ValidateTapeLineTask: URIRef
    cap_ApplyTapeStroke: URIRef
    cap_GetTool: URIRef
    cap_GoHome: URIRef
    cap_ManualTaping: URIRef
    cap_Recover: URIRef
    cap_ResumeTapeLine: URIRef
    cap_SandArea: URIRef
    cap_SandRaster: URIRef
    cap_ScanWalls: URIRef
    cap_ShowTapeLineStart: URIRef
    cap_SprayArea: URIRef
    cap_SprayRaster: URIRef
    cap_TapeJoint: URIRef
    cap_ValidateTapeLine: URIRef
    area: URIRef
    effect_areaSanded: URIRef
    effect_areaSprayed: URIRef
    effect_atHome: URIRef
    effect_lineInvalid: URIRef
    effect_lineTaped: URIRef
    effect_lineTapedManually: URIRef
    effect_lineValid: URIRef
    effect_toolMounted: URIRef
    line: URIRef
    location: URIRef
    opt_validateLines: URIRef
    p_home: URIRef
    p_manualLine: URIRef
    p_nextPendingLine: URIRef
    p_nextSandArea: URIRef
    p_nextSprayArea: URIRef
    p_robot: URIRef
    p_sander: URIRef
    p_sprayGun: URIRef
    p_tapingTool: URIRef
    p_validatedLine: URIRef
    q_featureById: URIRef
    q_featureCounts: URIRef
    q_featureStatus: URIRef
    q_hasPending: URIRef
    q_pendingJointLines: URIRef
    q_robotState: URIRef
    robot: URIRef
    sanding_afterScan: URIRef
    sanding_anyPending: URIRef
    sanding_end: URIRef
    sanding_endEarly: URIRef
    sanding_getTool: URIRef
    sanding_goHome: URIRef
    sanding_goHomeEarly: URIRef
    sanding_loop: URIRef
    sanding_morePending: URIRef
    sanding_recover: URIRef
    sanding_sand: URIRef
    sanding_scan: URIRef
    sanding_start: URIRef
    sanding_t01: URIRef
    sanding_t02: URIRef
    sanding_t03: URIRef
    sanding_t04: URIRef
    sanding_t05: URIRef
    sanding_t06: URIRef
    sanding_t07: URIRef
    sanding_t08: URIRef
    sanding_t09: URIRef
    sanding_t10: URIRef
    sanding_t11: URIRef
    sanding_t12: URIRef
    sanding_t13: URIRef
    sanding_t14: URIRef
    sanding_t15: URIRef
    spraying_afterScan: URIRef
    spraying_anyPending: URIRef
    spraying_end: URIRef
    spraying_endEarly: URIRef
    spraying_getTool: URIRef
    spraying_goHome: URIRef
    spraying_goHomeEarly: URIRef
    spraying_loop: URIRef
    spraying_morePending: URIRef
    spraying_recover: URIRef
    spraying_scan: URIRef
    spraying_spray: URIRef
    spraying_start: URIRef
    spraying_t01: URIRef
    spraying_t02: URIRef
    spraying_t03: URIRef
    spraying_t04: URIRef
    spraying_t05: URIRef
    spraying_t06: URIRef
    spraying_t07: URIRef
    spraying_t08: URIRef
    spraying_t09: URIRef
    spraying_t10: URIRef
    spraying_t11: URIRef
    spraying_t12: URIRef
    spraying_t13: URIRef
    spraying_t14: URIRef
    spraying_t15: URIRef
    taping_afterScan: URIRef
    taping_anyPending: URIRef
    taping_end: URIRef
    taping_endEarly: URIRef
    taping_getTool: URIRef
    taping_goHome: URIRef
    taping_goHomeEarly: URIRef
    taping_loop: URIRef
    taping_manual: URIRef
    taping_morePending: URIRef
    taping_scan: URIRef
    taping_start: URIRef
    taping_t01: URIRef
    taping_t02: URIRef
    taping_t03: URIRef
    taping_t04: URIRef
    taping_t05: URIRef
    taping_t06: URIRef
    taping_t07: URIRef
    taping_t08: URIRef
    taping_t09: URIRef
    taping_t10: URIRef
    taping_t11: URIRef
    taping_t12: URIRef
    taping_t13: URIRef
    taping_t14: URIRef
    taping_t15: URIRef
    taping_t16: URIRef
    taping_t17: URIRef
    taping_t18: URIRef
    taping_t19: URIRef
    taping_t20: URIRef
    taping_tape: URIRef
    taping_tapeValidated: URIRef
    taping_validResult: URIRef
    taping_validate: URIRef
    taping_validateOption: URIRef
    tmpl_getToolAutomatically: URIRef
    tmpl_getToolAutomatically_1: URIRef
    tmpl_getToolAutomatically_2: URIRef
    tool: URIRef
    validateLines: URIRef


class SK(DefinedNamespace):
    """Skills and capabilities: skills, parameters, interfaces, the Part 10 state machine, devices, tools, templates (ontologies/skill.ttl)."""

    _fail = True
    _NS = Namespace("https://locem-bridge.example.org/ont/skill#")

    Arm: URIRef
    BaseKinematics: URIRef
    BasicSkill: URIRef
    Capability: URIRef
    CompositeSkill: URIRef
    Compressor: URIRef
    Constraint: URIRef
    Device: URIRef
    DifferentialDrive: URIRef
    Frame: URIRef
    Halt: URIRef
    Halted: URIRef
    HaltedToReady: URIRef
    Lift: URIRef
    Mecanum: URIRef
    MobileBase: URIRef
    Postcondition: URIRef
    Precondition: URIRef
    ProgramStateMachine: URIRef
    Ready: URIRef
    ReadyToHalted: URIRef
    ReadyToRunning: URIRef
    Reset: URIRef
    Resume: URIRef
    RosActionInterface: URIRef
    RosServiceInterface: URIRef
    Running: URIRef
    RunningToHalted: URIRef
    RunningToReady: URIRef
    RunningToSuspended: URIRef
    Scanner: URIRef
    Skill: URIRef
    SkillInterface: URIRef
    SkillMethod: URIRef
    SkillParameter: URIRef
    Start: URIRef
    State: URIRef
    StateMachine: URIRef
    StateTransition: URIRef
    Suspend: URIRef
    Suspended: URIRef
    SuspendedToHalted: URIRef
    SuspendedToReady: URIRef
    SuspendedToRunning: URIRef
    TaskTemplate: URIRef
    TemplateStep: URIRef
    ToolChanger: URIRef
    allowedValue: URIRef
    cap_ArmHome: URIRef
    cap_ArmToNamedPose: URIRef
    cap_ArmToWallReady: URIRef
    cap_ChangeToolAutomatically: URIRef
    cap_DetectWallFeatures: URIRef
    cap_DriveBase: URIRef
    cap_DriveBaseToNamedPose: URIRef
    cap_Lift: URIRef
    cap_MountToolByOperator: URIRef
    cap_MoveArm: URIRef
    cap_MoveArmLinear: URIRef
    cap_MoveArmPath: URIRef
    cap_MoveBaseRelative: URIRef
    cap_ResetArm: URIRef
    cap_ResetBase: URIRef
    cap_RunCompressor: URIRef
    cap_SetBasePose: URIRef
    cap_SetPayload: URIRef
    cap_SetPressure: URIRef
    cap_SetTcp: URIRef
    cap_StopAll: URIRef
    cap_StopCompressor: URIRef
    cap_SwitchSpray: URIRef
    cap_SwitchToolOutput: URIRef
    cap_Wait: URIRef
    causedBy: URIRef
    constraintText: URIRef
    datatype: URIRef
    defaultValue: URIRef
    deviceName: URIRef
    endpoint: URIRef
    expandedFrom: URIRef
    expandsTaskType: URIRef
    frameName: URIRef
    fromState: URIRef
    hasDevice: URIRef
    hasFrame: URIRef
    hasMethod: URIRef
    hasParameter: URIRef
    hasPostcondition: URIRef
    hasPrecondition: URIRef
    hasSkillInterface: URIRef
    hasState: URIRef
    hasStateMachine: URIRef
    hasStep: URIRef
    hasTcp: URIRef
    hasTool: URIRef
    hasTransition: URIRef
    invokesSkill: URIRef
    involvesOperator: URIRef
    isRealizedBySkill: URIRef
    isRequired: URIRef
    keywordOnly: URIRef
    kinematics: URIRef
    mass: URIRef
    maxValue: URIRef
    minValue: URIRef
    model: URIRef
    mountedOn: URIRef
    notOfferedBy: URIRef
    notOfferedReason: URIRef
    offsetRpy: URIRef
    offsetXyz: URIRef
    opcuaBrowseName: URIRef
    opcuaNodeId: URIRef
    parameterIndex: URIRef
    parameterName: URIRef
    protocol: URIRef
    providesCapability: URIRef
    providesSkill: URIRef
    reach: URIRef
    realizedBy: URIRef
    realizesCapability: URIRef
    requiresCapability: URIRef
    rosNamespace: URIRef
    skillName: URIRef
    sourceFile: URIRef
    sparql: URIRef
    stateNumber: URIRef
    stepArgument: URIRef
    stepIndex: URIRef
    summary: URIRef
    toState: URIRef
    toolLength: URIRef
    toolName: URIRef
    transitionNumber: URIRef
    unit: URIRef
    usesDevice: URIRef


GEO = Namespace("http://www.opengis.net/ont/geosparql#")

PREFIXES: Dict[str, Namespace] = {
    "rdf": Namespace(str(RDF)),
    "rdfs": Namespace(str(RDFS)),
    "owl": Namespace(str(OWL)),
    "xsd": Namespace(str(XSD)),
    "proc": Namespace(str(PROC)),
    "ppr": Namespace(str(PPR)),
    "plb": Namespace(str(PLB)),
    "sk": Namespace(str(SK)),
    "geo": GEO,
    "site": SITE,
}
