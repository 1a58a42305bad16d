// A minimal web host for @foxglove/studio-base's App (as the open-source studio-web package did).
(function () {
  const S = self; // the UMD bundle put its exports on the global object
  const h = React.createElement;
  const values = {};
  const listeners = {};
  const appConfiguration = {
    get: (k) => values[k],
    set: async (k, v) => { values[k] = v; (listeners[k] || []).forEach((cb) => cb(v)); },
    addChangeListener: (k, cb) => { (listeners[k] = listeners[k] || []).push(cb); },
    removeChangeListener: (k, cb) => { listeners[k] = (listeners[k] || []).filter((x) => x !== cb); },
  };
  const preset = window.BENDSENSE_LAYOUT;
  const now = new Date().toISOString();
  const layouts = { local: { bendsense: { id: "bendsense", name: "bendsense", permission: "CREATOR_WRITE",
    baseline: { data: preset, savedAt: now }, working: undefined, syncInfo: undefined } } };
  const layoutStorage = {
    list: async (ns) => Object.values(layouts[ns] || {}),
    get: async (ns, id) => (layouts[ns] || {})[id] || (id === "bendsense" ? layouts.local.bendsense : undefined),
    put: async (ns, layout) => { (layouts[ns] = layouts[ns] || {})[layout.id] = layout; return layout; },
    delete: async (ns, id) => { delete (layouts[ns] || {})[id]; },
    importLayouts: async () => {},
    migrateUnnamespacedLayouts: async () => {},
  };
  const dataSources = [new S.McapLocalDataSourceFactory(), new S.RemoteDataSourceFactory()];
  S.initI18n().then(() => {
    ReactDOM.render(
      h(S.App, {
        deepLinks: [window.location.href],
        appConfiguration,
        dataSources,
        layoutStorage,
        extensionLoaders: [],
        enableGlobalCss: true,
      }),
      document.getElementById("root"),
    );
  });
})();
