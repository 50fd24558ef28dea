/*
 * The keepout plugin for Open MCT (the nasa/openmct-tutorial pattern: a dictionary plugin, a historical and
 * a realtime telemetry provider), kept thin: the objects, their units and limits come from the server's
 * /api/objects (built from the flight dictionary), history from /api/history, live points from one
 * WebSocket (/api/realtime). Adds a limit provider (yellow/red from the dictionary) and the sky view.
 */
function KeepoutPlugin(run) {
    const NAMESPACE = 'keepout';
    let objectsPromise = null;

    function objects() {
        if (!objectsPromise) {
            objectsPromise = fetch('/api/objects').then((response) => response.json());
        }
        return objectsPromise;
    }

    function isKeepoutTelemetry(domainObject) {
        return domainObject.identifier.namespace === NAMESPACE && domainObject.telemetry !== undefined;
    }

    // ---- the realtime connection: one WebSocket, subscriptions by key, reconnect when it drops ----
    const listeners = {};  // key -> set of callbacks
    let socket = null;
    let reconnectTimer = null;

    function send(message) {
        if (socket && socket.readyState === WebSocket.OPEN) {
            socket.send(JSON.stringify(message));
        }
    }

    function connect() {
        socket = new WebSocket(location.origin.replace(/^http/, 'ws') + '/api/realtime');
        socket.onopen = function () {
            Object.keys(listeners).forEach((key) => send({op: 'subscribe', key: key}));
        };
        socket.onmessage = function (event) {
            const byKey = {};
            JSON.parse(event.data).forEach((point) => {
                (byKey[point.id] = byKey[point.id] || []).push(point);
            });
            Object.entries(byKey).forEach(([key, points]) => {
                (listeners[key] || []).forEach((callback) => callback(points));
            });
        };
        socket.onclose = function () {
            if (!reconnectTimer) {
                reconnectTimer = setTimeout(() => { reconnectTimer = null; connect(); }, 2000);
            }
        };
    }

    // ---- limits: GREEN inside yellow, YELLOW outside yellow, RED outside red (as the ground monitor) ----
    function violation(level, side, low, high) {
        return {
            cssClass: `is-limit--${side === 'high' ? 'upr' : 'lwr'} is-limit--${level}`,
            name: `${level === 'red' ? 'Red' : 'Yellow'} ${side === 'high' ? 'High' : 'Low'}`,
            low: low, high: high
        };
    }

    const limitProvider = {
        supportsLimits: (domainObject) => Boolean(domainObject.keepout && domainObject.keepout.limits),
        getLimitEvaluator: function (domainObject) {
            const limits = domainObject.keepout.limits;
            return {
                evaluate: function (datum) {
                    const value = datum && datum.value;
                    if (typeof value !== 'number') {
                        return undefined;
                    }
                    for (const level of ['red', 'yellow']) {
                        const [low, high] = limits[level];
                        if (high !== null && value > high) {
                            return violation(level, 'high', high, Number.POSITIVE_INFINITY);
                        }
                        if (low !== null && value < low) {
                            return violation(level, 'low', Number.NEGATIVE_INFINITY, low);
                        }
                    }
                    return undefined;
                }
            };
        },
        getLimits: function (domainObject) {
            const limits = domainObject.keepout.limits;
            const definition = {};
            [['WARNING', 'yellow'], ['CRITICAL', 'red']].forEach(([name, level]) => {
                const [low, high] = limits[level];
                if (low === null && high === null) { return; }
                // Open MCT wants both sides: an open side is an infinite bound
                definition[name] = {
                    low: {color: level, value: low === null ? Number.NEGATIVE_INFINITY : low},
                    high: {color: level, value: high === null ? Number.POSITIVE_INFINITY : high}
                };
            });
            return {limits: () => Promise.resolve(definition)};
        }
    };

    const telemetryProvider = {
        supportsRequest: isKeepoutTelemetry,
        supportsSubscribe: isKeepoutTelemetry,
        supportsBatching: () => true,
        request: function (domainObject, options) {
            const params = new URLSearchParams({start: options.start, end: options.end});
            if (options.strategy === 'latest') { params.set('strategy', 'latest'); }
            if (options.outline) { params.set('outline', options.outline); }
            return fetch(`/api/history/${domainObject.identifier.key}?${params}`)
                .then((response) => response.json());
        },
        subscribe: function (domainObject, callback) {
            const key = domainObject.identifier.key;
            if (!listeners[key]) {
                listeners[key] = new Set();
                send({op: 'subscribe', key: key});
            }
            listeners[key].add(callback);
            return function unsubscribe() {
                listeners[key].delete(callback);
                if (listeners[key].size === 0) {
                    delete listeners[key];
                    send({op: 'unsubscribe', key: key});
                }
            };
        }
    };

    // ---- the sky view: equirectangular map (RA 360..0 left to right, as the sky is seen) ----
    const BODY_COLOURS = {sun: '#ffcc33', moon: '#c8c8d8', earth: '#4f9dff', inertial: '#bb88ff'};

    function skyView(openmct, domainObject) {
        let canvas = null;
        let trail = [];
        let latest = null;
        let unsubscribe = null;
        let resizeObserver = null;
        const onBounds = (bounds, isTick) => { if (!isTick) { load(); } else { prune(bounds.start); draw(); } };

        function prune(start) {
            trail = trail.filter((p) => p.utc >= start);
        }

        function load() {
            const bounds = openmct.time.getBounds();
            telemetryProvider.request(domainObject, {start: bounds.start, end: bounds.end, outline: 'last'})
                .then((points) => {
                    trail = points;
                    latest = points.length ? points[points.length - 1] : latest;
                    draw();
                });
        }

        function xy(radec, width, height) {
            return [(360 - radec[0]) / 360 * width, (90 - radec[1]) / 180 * height];
        }

        function polyline(ctx, points, width, height) {
            // break the line where it wraps round RA 0/360
            let previous = null;
            ctx.beginPath();
            points.forEach((radec) => {
                if (!radec) { previous = null; return; }
                const [x, y] = xy(radec, width, height);
                if (previous === null || Math.abs(radec[0] - previous[0]) > 180) {
                    ctx.moveTo(x, y);
                } else {
                    ctx.lineTo(x, y);
                }
                previous = radec;
            });
        }

        function draw() {
            if (!canvas) { return; }
            const width = canvas.clientWidth || 600;
            const height = Math.max(120, Math.min(canvas.clientHeight || 300, width / 2));
            canvas.width = width;
            canvas.height = height;
            const ctx = canvas.getContext('2d');
            ctx.fillStyle = '#101418';
            ctx.fillRect(0, 0, width, height);
            ctx.strokeStyle = '#2c343c';
            ctx.lineWidth = 1;
            for (let ra = 0; ra <= 360; ra += 30) {
                ctx.beginPath(); ctx.moveTo(ra / 360 * width, 0); ctx.lineTo(ra / 360 * width, height); ctx.stroke();
            }
            for (let dec = -60; dec <= 60; dec += 30) {
                const y = (90 - dec) / 180 * height;
                ctx.beginPath(); ctx.moveTo(0, y); ctx.lineTo(width, y); ctx.stroke();
            }
            if (latest) {
                (latest.zones || []).forEach((zone) => {
                    const colour = BODY_COLOURS[zone.body] || '#ff5555';
                    ctx.strokeStyle = colour;
                    ctx.fillStyle = colour + '33';
                    ctx.lineWidth = 2;
                    polyline(ctx, zone.outline.concat([zone.outline[0]]), width, height);
                    ctx.stroke();
                    ctx.fill();
                    if (zone.centre) {
                        const [x, y] = xy(zone.centre, width, height);
                        ctx.fillStyle = colour;
                        ctx.fillText(zone.name, x + 4, y - 4);
                    }
                });
                Object.entries(latest.bodies || {}).forEach(([body, radec]) => {
                    if (!radec) { return; }
                    const [x, y] = xy(radec, width, height);
                    ctx.fillStyle = BODY_COLOURS[body] || '#fff';
                    ctx.beginPath(); ctx.arc(x, y, 4, 0, 2 * Math.PI); ctx.fill();
                });
            }
            ctx.strokeStyle = '#7dff9a';
            ctx.lineWidth = 2;
            polyline(ctx, trail.map((p) => p.boresight), width, height);
            ctx.stroke();
            if (latest && latest.target) {
                const [x, y] = xy(latest.target, width, height);
                ctx.strokeStyle = '#ffffff';
                ctx.strokeRect(x - 5, y - 5, 10, 10);
            }
            if (latest && latest.boresight) {
                const [x, y] = xy(latest.boresight, width, height);
                ctx.fillStyle = '#7dff9a';
                ctx.beginPath(); ctx.arc(x, y, 5, 0, 2 * Math.PI); ctx.fill();
            }
            ctx.fillStyle = '#d0d0d0';
            const margin = latest && latest.margin_min_deg !== null && latest.margin_min_deg !== undefined
                ? `${latest.margin_min_deg.toFixed(2)} deg` : '-';
            ctx.fillText(`boresight trail (green), target (square), zones by body; RA 360..0, Dec -90..90; ` +
                         `t = ${latest ? latest.onboard_s.toFixed(1) : '-'} s, min margin ${margin}`, 6, height - 6);
        }

        return {
            show: function (element) {
                canvas = document.createElement('canvas');
                canvas.className = 'keepout-sky';
                canvas.style.width = '100%';
                canvas.style.height = '100%';
                element.appendChild(canvas);
                load();
                unsubscribe = openmct.telemetry.subscribe(domainObject, (points) => {
                    trail = trail.concat(points);
                    latest = points[points.length - 1];
                    draw();
                }, {strategy: 'batch'});
                openmct.time.on('boundsChanged', onBounds);
                resizeObserver = new ResizeObserver(draw);
                resizeObserver.observe(element);
            },
            destroy: function () {
                if (unsubscribe) { unsubscribe(); }
                openmct.time.off('boundsChanged', onBounds);
                if (resizeObserver) { resizeObserver.disconnect(); }
                canvas = null;
            }
        };
    }

    return function install(openmct) {
        openmct.objects.addRoot({namespace: NAMESPACE, key: 'root'});
        // Views (plots, tables) keep their settings in their object: kept in this page's memory only, the
        // dictionary stays the server's.
        const edited = {};
        openmct.objects.addProvider(NAMESPACE, {
            get: (identifier) => objects().then((all) => {
                const object = edited[identifier.key] || all[identifier.key];
                if (!object) {
                    return {identifier: identifier, name: `missing: ${identifier.key}`, type: 'unknown'};
                }
                return JSON.parse(JSON.stringify(object));
            }),
            create: (domainObject) => { edited[domainObject.identifier.key] = domainObject; return Promise.resolve(true); },
            update: (domainObject) => { edited[domainObject.identifier.key] = domainObject; return Promise.resolve(true); }
        });
        openmct.types.addType('keepout.channel', {
            name: 'keepout telemetry channel', description: 'A channel of the keepout flight dictionary',
            cssClass: 'icon-telemetry'
        });
        openmct.types.addType('keepout.events', {
            name: 'keepout event stream', description: 'Events of the flight software', cssClass: 'icon-tabular-realtime'
        });
        openmct.types.addType('keepout.sky', {
            name: 'keepout sky view', description: 'Boresight trail and keep-out zones', cssClass: 'icon-image'
        });
        openmct.telemetry.addProvider(telemetryProvider);
        openmct.telemetry.addProvider(limitProvider);
        openmct.objectViews.addProvider({
            key: 'keepout.sky', name: 'Sky', cssClass: 'icon-image',
            canView: (domainObject) => domainObject.type === 'keepout.sky',
            view: (domainObject) => skyView(openmct, domainObject),
            priority: () => 1000
        });
        connect();
    };
}
