// The layout of the screenshot: tip force, pressure, the shape (nav_msgs/Path) in 3D, and the raw wrench.
window.BENDSENSE_LAYOUT = {
  configById: {
    "Plot!force": {
      title: "Tip force [N]",
      paths: [
        { value: "/bendsense/wrench.wrench.force.x", enabled: true, timestampMethod: "receiveTime", label: "Fx [N]" },
        { value: "/bendsense/wrench.wrench.force.y", enabled: true, timestampMethod: "receiveTime", label: "Fy [N]" },
      ],
      showXAxisLabels: true, showYAxisLabels: true, showLegend: true, legendDisplay: "floating",
      showPlotValuesInLegend: false, isSynced: true, xAxisVal: "timestamp", sidebarDimension: 240,
    },
    "Plot!pressure": {
      title: "Pressure [Pa]",
      paths: [{ value: "/bendsense/pressure.fluid_pressure", enabled: true, timestampMethod: "receiveTime", label: "pressure [Pa]" }],
      showXAxisLabels: true, showYAxisLabels: true, showLegend: true, legendDisplay: "floating",
      showPlotValuesInLegend: false, isSynced: true, xAxisVal: "timestamp", sidebarDimension: 240,
    },
    "Plot!shape": {
      title: "Shape at the current time: nav_msgs/Path /bendsense/shape, y against x [m]",
      paths: [{ value: "/bendsense/shape.poses[:].pose.position.y", enabled: true, timestampMethod: "receiveTime", label: "shape y [m]" }],
      xAxisVal: "currentCustom",
      xAxisPath: { value: "/bendsense/shape.poses[:].pose.position.x", enabled: true },
      minXValue: -0.01, maxXValue: 0.09, minYValue: 0, maxYValue: 0.1,
      showXAxisLabels: true, showYAxisLabels: true, showLegend: true, legendDisplay: "floating",
      showPlotValuesInLegend: false, isSynced: false, sidebarDimension: 240,
    },
    "RawMessages!wrench": { topicPath: "/bendsense/wrench", diffEnabled: false, diffMethod: "custom", diffTopicPath: "", showFullMessageForDiff: false },
  },
  globalVariables: {},
  userNodes: {},
  playbackConfig: { speed: 1 },
  layout: {
    direction: "row",
    first: { direction: "column", first: "Plot!force", second: "Plot!pressure", splitPercentage: 60 },
    second: { direction: "column", first: "Plot!shape", second: "RawMessages!wrench", splitPercentage: 60 },
    splitPercentage: 60,
  },
};
