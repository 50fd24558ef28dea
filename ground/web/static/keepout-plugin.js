/*
 * The keepout plugin for Open MCT (the nasa/openmct-tutorial pattern: a dictionary plugin, a historical and
 * a realtime telemetry provider), kept thin: the objects, their names, units, display resolution and limits
 * come from the server's /api/objects (built from the flight dictionary and the run's mission), history from
 * /api/history, live points from one WebSocket (/api/realtime), alarms from /api/alarms. Adds a limit
 * provider (yellow/red from the dictionary), an onboard time system (a replay plotted on the packets' own
 * clock), the sky view and the alarm view.
 */

/*
 * Sky geometry, kept free of the page so the browser test can call it: an equirectangular map of RA 360..0
 * (left to right, as the sky is seen) and Dec 90..-90.
 */
const KeepoutSky = {
    // A boresight trail as segments that never cross the map: a step of over 180 deg in RA is the wrap
    // through 0/360, where the line breaks; a missing point breaks it too.
    trailSegments: function (points) {
        const segments = [];
        let current = [];
        let previous = null;
        points.forEach((radec) => {
            if (!radec || (previous && Math.abs(radec[0] - previous[0]) > 180)) {
                if (current.length) { segments.push(current); }
                current = [];
            }
            if (radec) { current.push(radec); }
            previous = radec;
        });
        if (current.length) { segments.push(current); }
        return segments;
    },
    // A zone outline as one closed ring with continuous RA (it may run past 0 or 360: the caller draws it
    // again shifted by 360 deg). An outline round a pole turns through 360 deg of RA: it is closed along
    // the map's top or bottom edge, so the fill covers the pole.
    zoneRing: function (outline) {
        const ring = [];
        outline.forEach((radec) => {
            if (!radec) { return; }
            let ra = radec[0];
            if (ring.length) {
                const last = ring[ring.length - 1][0];
                ra += 360 * Math.round((last - ra) / 360);
            }
            ring.push([ra, radec[1]]);
        });
        if (ring.length < 3) { return {ring: ring, pole: 0}; }
        const first = ring[0];
        let closing = first[0] - ring[ring.length - 1][0];
        closing -= 360 * Math.round(closing / 360);
        const turn = ring[ring.length - 1][0] + closing - first[0];
        if (Math.abs(turn) < 180) { return {ring: ring, pole: 0}; }
        const pole = ring.reduce((sum, p) => sum + p[1], 0) >= 0 ? 90 : -90;
        const end = ring[ring.length - 1][0] + closing;
        ring.push([end, pole], [first[0], pole]);
        return {ring: ring, pole: pole};
    }
};

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
            const params = new URLSearchParams({start: options.start, end: options.end,
                                                domain: options.domain || 'utc'});
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
    const LABEL_COLOUR = '#9aa4ae';

    function skyView(openmct, domainObject) {
        let canvas = null;
        let trail = [];
        let latest = null;
        let unsubscribe = null;
        let resizeObserver = null;
        const onBounds = (bounds, isTick) => { if (!isTick) { load(); } else { prune(bounds.start); draw(); } };

        function prune(start) {
            const domain = openmct.time.getTimeSystem().key;
            trail = trail.filter((p) => p[domain] >= start);
        }

        function load() {
            const bounds = openmct.time.getBounds();
            telemetryProvider.request(domainObject, {start: bounds.start, end: bounds.end, outline: 'last',
                                                     domain: openmct.time.getTimeSystem().key})
                .then((points) => {
                    trail = points;
                    latest = points.length ? points[points.length - 1] : latest;
                    draw();
                });
        }

        function draw() {
            if (!canvas) { return; }
            const width = canvas.clientWidth || 600;
            const height = Math.max(120, Math.min(canvas.clientHeight || 300, width / 2));
            canvas.width = width;
            canvas.height = height;
            const left = 34;
            const bottom = 30;  // room for the Dec and RA labels and the caption
            const mapW = width - left;
            const mapH = height - bottom;
            const x = (ra) => left + (360 - ra) / 360 * mapW;
            const y = (dec) => (90 - dec) / 180 * mapH;
            const ctx = canvas.getContext('2d');
            ctx.fillStyle = '#101418';
            ctx.fillRect(0, 0, width, height);
            grid(ctx, x, y, left, mapW, mapH);
            ctx.save();
            ctx.beginPath(); ctx.rect(left, 0, mapW, mapH); ctx.clip();
            if (latest) {
                (latest.zones || []).forEach((zone) => drawZone(ctx, zone, x, y));
                Object.entries(latest.bodies || {}).forEach(([body, radec]) => {
                    if (!radec) { return; }
                    ctx.fillStyle = BODY_COLOURS[body] || '#fff';
                    ctx.beginPath(); ctx.arc(x(radec[0]), y(radec[1]), 4, 0, 2 * Math.PI); ctx.fill();
                });
            }
            ctx.strokeStyle = '#7dff9a';
            ctx.lineWidth = 2;
            KeepoutSky.trailSegments(trail.map((p) => p.boresight)).forEach((segment) => {
                ctx.beginPath();
                segment.forEach(([ra, dec], i) => (i ? ctx.lineTo : ctx.moveTo).call(ctx, x(ra), y(dec)));
                ctx.stroke();
            });
            if (latest && latest.target) {
                ctx.strokeStyle = '#ffffff';
                ctx.strokeRect(x(latest.target[0]) - 5, y(latest.target[1]) - 5, 10, 10);
            }
            if (latest && latest.boresight) {
                ctx.fillStyle = '#7dff9a';
                ctx.beginPath(); ctx.arc(x(latest.boresight[0]), y(latest.boresight[1]), 5, 0, 2 * Math.PI); ctx.fill();
            }
            ctx.restore();
            ctx.fillStyle = '#d0d0d0';
            const margin = latest && latest.margin_min_deg !== null && latest.margin_min_deg !== undefined
                ? `${latest.margin_min_deg.toFixed(2)} deg` : '-';
            ctx.fillText(`boresight trail (green), target (square), zones by body (physical, not inflated); ` +
                         `t = ${latest ? latest.onboard_s.toFixed(1) : '-'} s onboard, smallest margin ${margin} ` +
                         `(onboard estimate)`, 6, height - 4);
        }

        function grid(ctx, x, y, left, mapW, mapH) {
            ctx.strokeStyle = '#2c343c';
            ctx.lineWidth = 1;
            ctx.fillStyle = LABEL_COLOUR;
            ctx.font = '10px sans-serif';
            ctx.textAlign = 'center';
            for (let ra = 0; ra <= 360; ra += 30) {
                ctx.beginPath(); ctx.moveTo(x(ra), 0); ctx.lineTo(x(ra), mapH); ctx.stroke();
                ctx.fillText(`${ra}\u00b0`, Math.min(Math.max(x(ra), left + 12), left + mapW - 12), mapH + 11);
            }
            ctx.textAlign = 'right';
            for (let dec = -60; dec <= 60; dec += 30) {
                ctx.beginPath(); ctx.moveTo(left, y(dec)); ctx.lineTo(left + mapW, y(dec)); ctx.stroke();
                ctx.fillText(`${dec > 0 ? '+' : ''}${dec}\u00b0`, left - 4, y(dec) + 3);
            }
            ctx.textAlign = 'start';
            ctx.fillText('RA', left + mapW - 14, mapH - 4);
            ctx.fillText('Dec', left + 2, 10);
        }

        function drawZone(ctx, zone, x, y) {
            const colour = BODY_COLOURS[zone.body] || '#ff5555';
            const {ring} = KeepoutSky.zoneRing(zone.outline);
            if (ring.length < 3) { return; }
            ctx.strokeStyle = colour;
            ctx.fillStyle = colour + '33';
            ctx.lineWidth = 2;
            [-360, 0, 360].forEach((shift) => {  // a zone across RA 0/360 shows on both edges of the map
                ctx.beginPath();
                ring.forEach(([ra, dec], i) => (i ? ctx.lineTo : ctx.moveTo).call(ctx, x(ra + shift), y(dec)));
                ctx.closePath();
                ctx.fill();
                ctx.stroke();
            });
            if (zone.centre) {
                ctx.fillStyle = colour;
                ctx.fillText(zone.name, x(zone.centre[0]) + 4, y(zone.centre[1]) - 4);
            }
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

    // ---- the alarm view: every alarm of the run, newest first, each acknowledged by the operator ----
    const SEVERITY_COLOURS = {RED: '#ff4d4d', FATAL: '#ff4d4d', YELLOW: '#ffcc33', WARNING_HI: '#ffcc33'};

    function alarmView() {
        let root = null;
        let timer = null;

        function acknowledge(body) {
            return fetch('/api/alarms/ack', {method: 'POST', headers: {'Content-Type': 'application/json'},
                                             body: JSON.stringify(body)})
                .then((response) => response.json()).then(render);
        }

        function cell(row, text, className) {
            const td = document.createElement('td');
            td.textContent = text;
            if (className) { td.className = className; }
            row.appendChild(td);
            return td;
        }

        function render(book) {
            if (!root) { return; }
            root.innerHTML = '';
            const header = document.createElement('div');
            header.className = 'keepout-alarms__header';
            header.textContent = `${book.unacknowledged} unacknowledged of ${book.alarms.length} alarms `;
            const all = document.createElement('button');
            all.className = 'c-button keepout-alarms__ack-all';
            all.textContent = 'Acknowledge all';
            all.disabled = book.unacknowledged === 0;
            all.onclick = () => acknowledge({all: true});
            header.appendChild(all);
            root.appendChild(header);
            const table = document.createElement('table');
            table.className = 'keepout-alarms__table';
            const head = table.insertRow();
            ['Onboard t [s]', 'Severity', 'Source', 'Message', 'State', ''].forEach((h) => cell(head, h, 'keepout-alarms__th'));
            book.alarms.slice().reverse().forEach((alarm) => {
                const row = table.insertRow();
                row.className = 'keepout-alarms__row' + (alarm.acknowledged ? ' is-acknowledged' : ' is-unacknowledged');
                row.dataset.alarmId = alarm.alarm_id;
                cell(row, alarm.onboard_s.toFixed(1));
                cell(row, alarm.severity, 'keepout-alarms__severity').style.color = SEVERITY_COLOURS[alarm.severity] || '';
                cell(row, alarm.source);
                cell(row, alarm.message, 'keepout-alarms__message');
                cell(row, alarm.cleared_onboard_s === null ? 'active' : `cleared ${alarm.cleared_onboard_s.toFixed(1)} s`);
                const action = cell(row, '');
                if (alarm.acknowledged) {
                    action.textContent = 'acknowledged';
                } else {
                    const button = document.createElement('button');
                    button.className = 'c-button keepout-alarms__ack';
                    button.textContent = 'Acknowledge';
                    button.onclick = () => acknowledge({ids: [alarm.alarm_id]});
                    action.appendChild(button);
                }
            });
            root.appendChild(table);
        }

        function poll() {
            fetch('/api/alarms').then((response) => response.json()).then(render).catch(() => {});
        }

        return {
            show: function (element) {
                root = document.createElement('div');
                root.className = 'keepout-alarms';
                element.appendChild(root);
                poll();
                timer = setInterval(poll, 1000);
            },
            destroy: function () {
                clearInterval(timer);
                root = null;
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
        openmct.types.addType('keepout.alarms', {
            name: 'keepout alarms', description: 'Limit violations, FDIR trips and keep-out events to acknowledge',
            cssClass: 'icon-alert-triangle'
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
        openmct.objectViews.addProvider({
            key: 'keepout.alarms', name: 'Alarms', cssClass: 'icon-alert-triangle',
            canView: (domainObject) => domainObject.type === 'keepout.alarms',
            view: () => alarmView(),
            priority: () => 1000
        });
        // Onboard time: seconds since the mission start on the packets' own clock, what a replay is read in.
        openmct.telemetry.addFormat({
            key: 'keepout.onboard',
            format: (value) => (typeof value === 'number' ? `${value.toFixed(1)} s` : value),
            parse: (text) => (typeof text === 'number' ? text : parseFloat(String(text))),
            validate: (text) => !Number.isNaN(parseFloat(String(text)))
        });
        openmct.time.addTimeSystem({key: 'onboard_s', name: 'Onboard time', cssClass: 'icon-clock',
                                    timeFormat: 'keepout.onboard', durationFormat: 'keepout.onboard',
                                    isUTCBased: false});
        connect();
    };
}
